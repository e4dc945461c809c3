"""The bus scanner through Channel Access (pyepics) and real processes: `beamctl scanner` runs the
simulated bus of examples/scanner (13 terminals and their plant); three IOCs attach to it (A and B
as in the example, C an observer that claims no output). Each sees its own slaves; outputs of A
and B land in one frame and come back through the plant's wires; a second claim of A's outputs is
refused naming both IOCs; SIGKILL of A leaves B's and C's cycles running without a gap, its
outputs go to zero, and A started again reattaches; a stopped IOC's queue drops are counted on it
alone; a scanner restart makes every IOC's bus data INVALID and the IOCs reattach by themselves."""

import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import epics
import pytest

from conftest import (BEAMCTL, REPO_ROOT, RunServer, ScannerServer, acquire_port, connect, forget_pvs, new_prefix,
                      not_connecting, release_port, require_binary, wait_for)

EXAMPLE = REPO_ROOT / "examples" / "scanner"
BLADE = REPO_ROOT / "examples" / "demo" / "axes" / "blade.yaml"

IOC_C = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: scanner, socket: {socket}, slaves: [OUTA, OUTB, ECHO], claims: none}}
"""

IOC_D = """
ioc: {{name: {name}, prefix: "{prefix}"}}
buses:
  - id: 0
    link: {{type: scanner, socket: {socket}, claims: ["OUTA:binaryOutput02"]}}
    slaves:
      - {{position: 2, type: EL2008, name: OUTA}}
"""


def get(name, **kw):
    return epics.caget(name, timeout=5, **kw)


class Setup:
    """The scanner and three IOCs, their files in `tmp`, each IOC on its own CA port."""

    def __init__(self, tmp):
        self.tmp = Path(tmp)
        self.socket = str(self.tmp / "scanner.sock")
        scanner = (EXAMPLE / "scanner.yaml").read_text()
        scanner = re.sub(r"socket: [^\s,}]+", f"socket: {self.socket}", scanner)
        scanner = scanner.replace("depth: 64", "depth: 1024")  # a loaded CI machine must not drop cycles
        (self.tmp / "scanner.yaml").write_text(scanner)
        shutil.copy(EXAMPLE / "plant.yaml", self.tmp / "plant.yaml")
        self.p = {k: new_prefix() for k in "ABCD"}
        for k, src in (("A", "ioc_a.yaml"), ("B", "ioc_b.yaml")):
            text = (EXAMPLE / src).read_text()
            text = re.sub(r"socket: [^\s,}]+", f"socket: {self.socket}", text)
            text = text.replace("../demo/axes/blade.yaml", str(BLADE))
            name = self.p[k].rstrip(":")
            text = re.sub(r"ioc: \{name: \w+, prefix: \"\w+:\"\}", f'ioc: {{name: {name}, prefix: "{self.p[k]}"}}', text)
            (self.tmp / f"ioc_{k.lower()}.yaml").write_text(text)
        for k, text in (("C", IOC_C), ("D", IOC_D)):
            (self.tmp / f"ioc_{k.lower()}.yaml").write_text(
                text.format(name=self.p[k].rstrip(":"), prefix=self.p[k], socket=self.socket))
        self.scanner = ScannerServer(self.tmp, self.tmp / "scanner.yaml")
        self.ports = {k: acquire_port() for k in "ABC"}
        self.iocs = {k: RunServer(self.tmp, self.tmp / f"ioc_{k.lower()}.yaml", self.ports[k]) for k in "ABC"}
        for k in "ABC":
            self.iocs[k].name = f"ioc_{k}"

    def pv(self, k, suffix):
        return self.p[k] + suffix

    def start(self):
        self.scanner.start()
        for k in "ABC":
            self.iocs[k].start()
        for k in "ABC":
            assert wait_for(lambda: get(self.pv(k, "m0-Stat-OK")) == 1, timeout=15), k
        return self

    def status(self):
        r = subprocess.run([str(BEAMCTL), "scanner", "status", self.socket], capture_output=True, text=True, timeout=10)
        assert r.returncode == 0, r.stderr
        return r.stdout

    def close(self):
        for srv in list(self.iocs.values()) + [self.scanner]:
            srv.stop()
            srv.kill()
        for k in "ABCD":
            forget_pvs(self.p[k])
        for port in self.ports.values():
            release_port(port)


@pytest.fixture(scope="module")
def bus(tmp_path_factory):
    require_binary()
    s = Setup(tmp_path_factory.mktemp("scanner"))
    try:
        yield s.start()
    finally:
        s.close()


def test_each_ioc_sees_its_own_slaves(bus):
    # A lists its slaves with their types; B names them only and gets the types from the scanner.
    assert get(bus.pv("A", "m0s003-HWType")) == "EL7041"
    assert get(bus.pv("B", "m0s005-HWType")) == "EL7041"
    assert get(bus.pv("B", "m0-SlvCntr")) == 6
    assert get(bus.pv("A", "m0-SlvCntr")) == 5
    assert not_connecting(bus.pv("A", "m0s005-HWType"))
    assert not_connecting(bus.pv("B", "m0s003-HWType"))
    for k in "ABC":
        assert get(bus.pv(k, "m0-ScnConn"), as_string=True) == "ATTACHED"
        assert get(bus.pv(k, "m0-LinkUp"), as_string=True) == "UP"
    # all 13 slaves answer on the scanner's bus
    assert get(bus.pv("A", "m0-SlvRsp")) == 13
    out = bus.status()
    assert "3 client(s)" in out, out
    for k in "ABC":
        assert bus.p[k].rstrip(":") in out, out


def test_outputs_of_two_iocs_land_in_one_frame(bus):
    assert epics.caput(bus.pv("A", "m0s002-BO01"), 1, wait=True, timeout=5)
    assert epics.caput(bus.pv("B", "m0s006-BO02"), 1, wait=True, timeout=5)
    # C claims nothing and sees both outputs as sent, and the plant's wires bring both back.
    assert wait_for(lambda: get(bus.pv("C", "m0s002-BO01")) == 1 and get(bus.pv("C", "m0s006-BO02")) == 1)
    assert wait_for(lambda: get(bus.pv("C", "m0s007-BI01")) == 1 and get(bus.pv("C", "m0s007-BI06")) == 1)
    assert get(bus.pv("A", "m0s007-BI06")) == 1 or wait_for(lambda: get(bus.pv("A", "m0s007-BI06")) == 1)
    # C's put to an output it did not claim never reaches the frame.
    epics.caput(bus.pv("C", "m0s002-BO03"), 1, wait=True, timeout=5)
    time.sleep(0.3)
    assert get(bus.pv("A", "m0s007-BI03")) == 0
    assert get(bus.pv("C", "m0s007-BI03")) == 0


def test_a_second_claim_is_refused_naming_both(bus):
    port = acquire_port()
    try:
        r = subprocess.run([str(BEAMCTL), "run", str(bus.tmp / "ioc_d.yaml"), "--ca-port", str(port), "--shell-socket", "none"],
                           capture_output=True, text=True, timeout=60)
    finally:
        release_port(port)
    assert r.returncode == 1, r.stdout + r.stderr
    a, d = bus.p["A"].rstrip(":"), bus.p["D"].rstrip(":")
    assert f"ec0 OUTA binaryOutput02 is claimed by '{a}'" in r.stderr, r.stderr
    assert f"'{d}'" in r.stderr and "cannot claim it too" in r.stderr, r.stderr
    assert "3 client(s)" in bus.status()


def test_an_axis_moves_on_the_shared_bus(bus):
    b0 = get(bus.pv("B", "StageB.RBV"))
    assert epics.caput(bus.pv("A", "StageA.CNEN"), 1, wait=True, timeout=5)  # the blade axis is not enabled at start
    assert wait_for(lambda: get(bus.pv("A", "StageA-EnaAct")) == 1, timeout=5)
    assert epics.caput(bus.pv("A", "StageA"), 3.0, wait=True, timeout=30)
    assert wait_for(lambda: abs(get(bus.pv("A", "StageA.RBV")) - 3.0) < 0.01)
    assert get(bus.pv("A", "StageA-ErrId")) == 0
    assert abs(get(bus.pv("B", "StageB.RBV")) - b0) < 0.01


def shell(bus, k, command):
    r = subprocess.run([str(BEAMCTL), "shell", bus.p[k].rstrip(":"), "-c", command], capture_output=True, text=True,
                       timeout=60)
    return r.returncode, r.stdout + r.stderr


def test_sdo_through_the_scanner(bus):
    # IOC A owns M1's outputs: it may write its CoE objects; the others may read any slave's.
    rc, out = shell(bus, "A", "sdo 0 3 0x8010 1 1200 2")
    assert rc == 0 and "ec0 s3 0x8010:01 := 1200 (2 bytes)" in out, out
    rc, out = shell(bus, "C", "sdo 0 3 0x8010 1")
    assert rc == 0 and "ec0 s3 0x8010:01 = 1200 (2 bytes: b0 04)" in out, out
    rc, out = shell(bus, "B", "sdo 0 3 0x8010 1")
    assert rc == 0 and "ec0 s3 0x8010:01 = 1200 (2 bytes: b0 04)" in out, out
    rc, out = shell(bus, "B", "sdo 0 3 0x8010 1 900 2")
    assert rc != 0 and "SDO writes only to a slave whose outputs this client claimed" in out, out
    rc, out = shell(bus, "A", "sdo 0 3 0x7777 1")
    assert rc != 0 and "0x7777:01 aborted: 0x06020000 object does not exist" in out, out
    rc, out = shell(bus, "A", "sdo 0 3 0x8010")
    assert rc != 0 and "usage: sdo BUS POSITION INDEX SUB [VALUE SIZE]" in out, out


def counters(bus, k):
    return {n: get(bus.pv(k, "m0-" + n)) for n in ("ScnCycle", "ScnMissed", "ScnDrops", "ScnAttaches")}


def test_sigkill_of_one_ioc_leaves_the_others_running_without_a_gap(bus):
    assert epics.caput(bus.pv("A", "m0s002-BO04"), 1, wait=True, timeout=5)
    assert wait_for(lambda: get(bus.pv("C", "m0s007-BI04")) == 1)
    before = {k: counters(bus, k) for k in "BC"}
    lost_before = re.search(r"frames lost (\d+)", bus.status()).group(1)
    bus.iocs["A"].kill()  # SIGKILL: no goodbye
    # Its claimed outputs go to zero (the scanner's detach policy); the wires show it.
    assert wait_for(lambda: get(bus.pv("C", "m0s002-BO04")) == 0 and get(bus.pv("C", "m0s007-BI04")) == 0)
    assert wait_for(lambda: "2 client(s)" in bus.status())
    # B and C run on for a second of the scanner's cycles (1 kHz), as they count them: however
    # long a loaded machine takes for it, not a second of this client's clock
    mid = {k: get(bus.pv(k, "m0-ScnCycle")) for k in "BC"}
    for k in "BC":
        assert wait_for(lambda: get(bus.pv(k, "m0-ScnCycle")) >= mid[k] + 1000, timeout=60), (k, mid)
    for k in "BC":
        after = counters(bus, k)
        assert after["ScnCycle"] > before[k]["ScnCycle"] + 500, (k, before[k], after)
        assert after["ScnMissed"] == before[k]["ScnMissed"] == 0, (k, after)
        assert after["ScnDrops"] == before[k]["ScnDrops"] == 0, (k, after)
        assert get(bus.pv(k, "m0-Stat-OK")) == 1
    assert re.search(r"frames lost (\d+)", bus.status()).group(1) == lost_before
    # A again: it reattaches and its outputs reach the frame.
    forget_pvs(bus.p["A"])
    bus.iocs["A"].start()
    assert wait_for(lambda: get(bus.pv("A", "m0-Stat-OK")) == 1, timeout=15)
    assert wait_for(lambda: "3 client(s)" in bus.status())
    assert epics.caput(bus.pv("A", "m0s002-BO04"), 1, wait=True, timeout=5)
    assert wait_for(lambda: get(bus.pv("C", "m0s007-BI04")) == 1)


def test_a_stopped_ioc_loses_its_own_cycles_counted(bus):
    c0, b0 = counters(bus, "C"), counters(bus, "B")
    bus.iocs["C"].signal(signal.SIGSTOP)
    try:
        # twice its ring of 1024 cycles, in the scanner's cycles (B, running, sees them)
        assert wait_for(lambda: get(bus.pv("B", "m0-ScnCycle")) >= b0["ScnCycle"] + 2048, timeout=60), b0
    finally:
        bus.iocs["C"].signal(signal.SIGCONT)
    assert wait_for(lambda: get(bus.pv("C", "m0-ScnDrops")) > c0["ScnDrops"], timeout=60)
    c1 = counters(bus, "C")
    assert c1["ScnDrops"] >= 500, c1
    assert c1["ScnMissed"] >= c1["ScnDrops"], c1
    b1 = counters(bus, "B")
    assert b1["ScnDrops"] == b0["ScnDrops"] == 0 and b1["ScnMissed"] == 0, b1
    m = re.search(re.escape(bus.p["C"].rstrip(":")) + r" \(pid \d+\): .* drops (\d+)", bus.status())
    assert m and int(m.group(1)) >= 500, bus.status()


def test_scanner_restart_invalid_then_reattached(bus):
    entry = bus.pv("B", "m0s007-BI01")
    assert get(bus.pv("B", "m0-ScnAttaches")) == 1
    assert bus.scanner.stop() == 0
    for k in "BC":
        assert wait_for(lambda: get(bus.pv(k, "m0-ScnConn"), as_string=True) == "DETACHED"), k
        assert wait_for(lambda: get(bus.pv(k, "m0-Stat-OK")) == 0), k
    assert wait_for(lambda: get(entry + ".SEVR", as_string=True) == "INVALID")
    assert get(entry + ".STAT", as_string=True) == "COMM"
    assert get(bus.pv("B", "m0s005-Valid"), as_string=True) == "INVALID"
    # the axis on it stops as on bus loss
    assert wait_for(lambda: get(bus.pv("B", "StageB-ErrId")) != 0)
    bus.scanner.start()
    for k in "ABC":
        assert wait_for(lambda: get(bus.pv(k, "m0-ScnConn"), as_string=True) == "ATTACHED", timeout=15), k
        assert wait_for(lambda: get(bus.pv(k, "m0-Stat-OK")) == 1, timeout=15), k
    assert get(bus.pv("B", "m0-ScnAttaches")) == 2
    assert wait_for(lambda: get(entry + ".SEVR", as_string=True) == "NO_ALARM")
    # B's outputs are its own again: its put comes back through the wires
    assert epics.caput(bus.pv("B", "m0s006-BO03"), 1, wait=True, timeout=5)
    assert wait_for(lambda: get(bus.pv("C", "m0s007-BI07")) == 1)


SCANNER_RAW = """
scanner: {{name: veth-scanner, socket: {socket}}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: raw, iface: {iface}}}
    slaves:
      - {{position: 0, type: EK1100, name: COUPLER}}
      - {{position: 1, type: EL2008, name: OUT}}
      - {{position: 2, type: EL1008, name: IN}}
"""

IOC_RAW = """
ioc: {{name: {name}, prefix: "{prefix}"}}
buses:
  - id: 0
    link: {{type: scanner, socket: {socket}, slaves: [{slaves}], claims: {claims}}}
"""


def test_over_veth_two_iocs_share_a_raw_bus(require_netns, tmp_path):
    """The scanner on `link: {type: raw}` to `beamctl sim --iface` in a network namespace (the
    dio.yaml segment: EL2008 outputs 1-4 wired to EL1008 inputs 1-4): IOC W writes the outputs, IOC
    R only reads; W's output comes back to R through the wire and the scanner's frame on the veth."""
    from test_veth import SimServer, VethPair
    require_binary()
    net = VethPair()
    sim = scn = None
    iocs, ports, prefixes = [], [], []
    try:
        why = net.up()
        if why:
            pytest.skip(f"cannot create a network namespace and veth pair here ({why}); "
                        "this test needs root or CAP_SYS_ADMIN + CAP_NET_ADMIN + CAP_NET_RAW")
        sim = SimServer(tmp_path, net.ns, net.segment_end).start()
        socket = str(tmp_path / "s.sock")
        (tmp_path / "scanner.yaml").write_text(SCANNER_RAW.format(socket=socket, iface=net.master_end))
        scn = ScannerServer(tmp_path, tmp_path / "scanner.yaml").start()
        for k, slaves, claims in (("w", "OUT", "all"), ("r", "OUT, IN", "none")):
            p = new_prefix()
            prefixes.append(p)
            cfg = tmp_path / f"ioc_{k}.yaml"
            cfg.write_text(IOC_RAW.format(name=p.rstrip(":"), prefix=p, socket=socket, slaves=slaves, claims=claims))
            ports.append(acquire_port())
            iocs.append(RunServer(tmp_path, cfg, ports[-1]).start())
        w, r = prefixes
        assert wait_for(lambda: get(r + "m0-Stat-OK") == 1 and get(w + "m0-Stat-OK") == 1, timeout=15)
        # the count of answering slaves is published on its own, after the status (a loaded VM)
        assert wait_for(lambda: get(r + "m0-SlvRsp") == 3, timeout=5), get(r + "m0-SlvRsp")
        assert get(r + "m0s002-BI02") == 0
        assert epics.caput(w + "m0s001-BO02", 1, wait=True, timeout=5)
        assert wait_for(lambda: get(r + "m0s002-BI02") == 1, timeout=5), "W's output over the veth, back to R"
        assert get(r + "m0s001-BO02") == 1  # R sees W's output as sent
        assert epics.caput(w + "m0s001-BO02", 0, wait=True, timeout=5)
        assert wait_for(lambda: get(r + "m0s002-BI02") == 0, timeout=5)
    finally:
        for srv in iocs + [scn, sim]:
            if srv is not None:
                srv.stop()
                srv.kill()
        for p in prefixes:
            forget_pvs(p)
        for port in ports:
            release_port(port)
        net.down()


def test_check_takes_scanner_files_and_scanner_iocs(tmp_path):
    require_binary()

    def check(path):
        return subprocess.run([str(BEAMCTL), "check", str(path)], capture_output=True, text=True, timeout=60)

    r = check(EXAMPLE / "scanner.yaml")
    assert r.returncode == 0 and "scanner.yaml: OK (a scanner file, 1 bus(es))" in r.stdout, r.stdout + r.stderr
    r = check(EXAMPLE / "ioc_a.yaml")  # slaves listed with their types: checked without the scanner
    assert r.returncode == 0 and "OK (202 PVs, 1 bus(es))" in r.stdout, r.stdout + r.stderr
    bad = tmp_path / "scanner.yaml"
    bad.write_text((EXAMPLE / "scanner.yaml").read_text().replace("type: EL3104", "type: EL3999"))
    shutil.copy(EXAMPLE / "plant.yaml", tmp_path / "plant.yaml")
    r = check(bad)
    assert r.returncode == 1 and "bus 0 position 10: unknown device type 'EL3999'" in r.stderr, r.stderr
    # an IOC naming its slaves only through the scanner cannot be checked without it, and says why
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(IOC_C.format(name="CHK", prefix="CHK:", socket=tmp_path / "none.sock"))
    r = check(ioc)
    assert r.returncode == 1, r.stdout
    assert "link.slaves are named by the scanner when the IOC starts: start the scanner first" in r.stderr, r.stderr


def test_the_socket_belongs_to_the_files_group(tmp_path):
    require_binary()
    import grp
    import stat
    group = grp.getgrgid(1).gr_name  # a group every Debian system has (daemon)
    cfg = (EXAMPLE / "scanner.yaml").read_text()
    cfg = re.sub(r"socket: [^\s,}]+", f"socket: {tmp_path}/s.sock\n  socket_group: {group}", cfg, count=1)
    (tmp_path / "scanner.yaml").write_text(cfg)
    shutil.copy(EXAMPLE / "plant.yaml", tmp_path / "plant.yaml")
    srv = ScannerServer(tmp_path, tmp_path / "scanner.yaml").start()
    try:
        st = os.stat(tmp_path / "s.sock")
        assert stat.S_ISSOCK(st.st_mode) and stat.S_IMODE(st.st_mode) == 0o660 and st.st_gid == 1, oct(st.st_mode)
        # a second scanner on the same socket is refused, naming it
        r = subprocess.run([str(BEAMCTL), "scanner", str(tmp_path / "scanner.yaml")], capture_output=True, text=True, timeout=30)
        assert r.returncode == 1 and f"scanner socket {tmp_path}/s.sock: in use by another running process" in r.stderr, r.stderr
    finally:
        srv.stop()
        srv.kill()
    (tmp_path / "bad.yaml").write_text(cfg.replace(f"socket_group: {group}", "socket_group: no-such-group-xyz"))
    r = subprocess.run([str(BEAMCTL), "scanner", str(tmp_path / "bad.yaml")], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1 and "scanner.socket_group: 'no-such-group-xyz' is no group on this system" in r.stderr, r.stderr


def test_an_ioc_at_another_rate_is_refused(tmp_path):
    require_binary()
    cfg = (EXAMPLE / "scanner.yaml").read_text()
    cfg = re.sub(r"socket: [^\s,}]+", f"socket: {tmp_path}/s.sock", cfg)
    (tmp_path / "scanner.yaml").write_text(cfg)
    shutil.copy(EXAMPLE / "plant.yaml", tmp_path / "plant.yaml")
    (tmp_path / "ioc.yaml").write_text(IOC_C.format(name="RATE", prefix="RATE:", socket=f"{tmp_path}/s.sock")
                                       .replace("engine: {rate_hz: 1000}", "engine: {rate_hz: 500}"))
    port = acquire_port()
    srv = ScannerServer(tmp_path, tmp_path / "scanner.yaml")
    try:
        srv.start()
        r = subprocess.run([str(BEAMCTL), "run", str(tmp_path / "ioc.yaml"), "--ca-port", str(port), "--shell-socket", "none"],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 1, r.stdout + r.stderr
        assert "the scanner cycles bus 0 at 1000 Hz, this IOC's engine at 500 Hz: set engine.rate_hz to 1000" in r.stderr, r.stderr
    finally:
        release_port(port)
        srv.stop()
        srv.kill()
