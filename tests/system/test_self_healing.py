"""The self-healing bus through Channel Access (pyepics) and the fault commands: an IOC that starts
with a configured drive unpowered (link.faults) serves everything else, shows that slave MISSING and
its entries COMM/INVALID, and brings it to OP with its start-up SDO when it is powered; a drive
power-cycled while another axis moves leaves that move undisturbed; `beamctl sim --control` takes
faults from `beamctl sim fault`; `strict: true` keeps the refusal."""

import os
import shutil
import subprocess
import time
from pathlib import Path

import epics
from epics import ca

from conftest import (BEAMCTL, RunServer, acquire_port, connect, end_process, forget_pvs, release_port,
                      require_binary, wait_for)

DATA = Path(__file__).parent / "data" / "axes"

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
{strict}    link: {{type: sim, plant: plant.yaml, faults: [{faults}]}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
      - {{position: 2, type: EL7041}}
      - {{position: 3, type: EL1008}}
      - {{position: 4, type: EL7041, sdo: [{{index: 0x8010, sub: 1, value: 1200, size: 2}}]}}
axes:
  - {{file: stepper.yaml, macros: {{AX_NAME: X, DRV_SLAVE: 2}}}}
  - {{file: stepper_y.yaml, macros: {{AX_NAME: Y, DRV_SLAVE: 4}}}}
plcs:
  - {{id: 0, file: on_s4.plc, rate_ms: 10}}
  - {{id: 1, file: on_s2.plc, rate_ms: 10}}
"""

PLANT = """
stages:
  - name: x
    drive: s2
    travel: [-60, 60]
    limits:
      forward: {input: s1.binaryInput01, at: 50}
      backward: {input: s1.binaryInput02, at: -50}
  - name: y
    drive: s4
    travel: [-60, 60]
    limits:
      forward: {input: s3.binaryInput01, at: 50}
      backward: {input: s3.binaryInput02, at: -50}
"""


class Ioc:
    def __init__(self, tmp_path, prefix, faults="", strict=False):
        shutil.copy(DATA / "stepper.yaml", tmp_path / "stepper.yaml")
        (tmp_path / "plant.yaml").write_text(PLANT)
        (tmp_path / "on_s4.plc").write_text("static.p := ec0.s4.positionActual01;\n")  # the drive that may be out
        (tmp_path / "on_s2.plc").write_text("static.p := ec0.s2.positionActual01;\n")
        text = IOC.format(name=prefix.rstrip(":"), prefix=prefix, faults=faults,
                          strict="    strict: true\n" if strict else "")
        # the second axis: same file, id 2, its switches on the second EL1008
        stepper = (tmp_path / "stepper.yaml").read_text()
        assert "  id: 1\n" in stepper and "ec0.s1." in stepper
        (tmp_path / "stepper_y.yaml").write_text(stepper.replace("  id: 1\n", "  id: 2\n").replace("ec0.s1.", "ec0.s3."))
        self.cfg = tmp_path / "ioc.yaml"
        self.cfg.write_text(text)
        self.tmp, self.prefix = tmp_path, prefix
        self.port = acquire_port()
        self.srv = RunServer(tmp_path, self.cfg, self.port)

    def __enter__(self):
        self.srv.start()
        return self

    def __exit__(self, *exc):
        self.srv.stop()
        self.srv.kill()
        forget_pvs(self.prefix)
        release_port(self.port)

    def shell(self, command):
        r = subprocess.run([str(BEAMCTL), "shell", self.prefix.rstrip(":"), "-c", command],
                           capture_output=True, text=True, timeout=60)
        return r.returncode, r.stdout + r.stderr


def get(name, as_string=False):
    if as_string:  # an enum's state string (ca.get gives the number)
        connect(name)
        return epics.caget(name, as_string=True, timeout=5)
    return ca.get(connect(name))


def put(name, value):
    assert ca.put(connect(name), value, wait=True) == 1, name


def test_start_with_a_drive_unpowered_then_power_it(tmp_path, prefix):
    require_binary()
    p = prefix
    with Ioc(tmp_path, prefix, faults='"power 4 off"') as ioc:
        err = ioc.srv.stderr()
        assert "ec0 position 4: missing (expected EL7041, vendor 0x00000002, product 0x1b813052" in err, err
        assert "starting without it" in err
        assert wait_for(lambda: get(p + "m0-SlvOP") == 4)
        assert get(p + "m0-Stat-OK") == 0                  # not every configured slave is there
        assert get(p + "m0s004-State", as_string=True) == "MISSING"
        assert get(p + "m0s004-ErrId") == 0x24012
        assert get(p + "m0s004-Valid") == 0
        assert get(p + "m0s002-Valid") == 1
        assert get(p + "m0-SlvRsp") == 4
        # the missing drive's entries: COMM/INVALID; the others' fine
        pos = p + "m0s004-positionActual01"
        assert get(pos + ".SEVR", as_string=True) == "INVALID"
        assert get(pos + ".STAT", as_string=True) == "COMM"
        assert get(p + "m0s002-positionActual01.SEVR", as_string=True) == "NO_ALARM"
        # the axis on it is disabled with ECMC's hardware error; the other one moves
        assert get(p + "Y-ErrId") == 0x14315
        put(p + "X-EnaCmd", 1)
        assert wait_for(lambda: get(p + "X-EnaAct") == 1)
        rc, out = ioc.shell("ethercat 0")
        assert rc == 0 and "s4 EL7041: MISSING, not valid" in out, out
        assert get(p + "m0s004-ErrMsg").startswith("ec0 position 4: missing (expected EL70")
        # the PLC reading the missing drive is held with ECMC's entry error; the other one runs
        assert wait_for(lambda: get(p + "PLC01-Scans") > 10)
        assert get(p + "PLC01-Err") == 0
        assert get(p + "PLC00-Err") == 0x2100E
        assert get(p + "PLC00-Scans") == 0
        # powered: it joins, its start-up SDO written, without a restart
        rc, out = ioc.shell("sim 0 power 4 on")
        assert rc == 0 and "ec0: power 4 on (applied at the next frame)" in out, out
        assert wait_for(lambda: get(p + "m0s004-State", as_string=True) == "OP", timeout=20)
        assert wait_for(lambda: get(p + "m0-Stat-OK") == 1, timeout=5)
        assert get(p + "m0s004-ReconfCntr") == 1
        assert get(p + "m0s004-ErrId") == 0
        assert wait_for(lambda: get(p + "PLC00-Scans") > 0)  # its slave is back: it runs, error cleared
        assert get(p + "PLC00-Err") == 0
        assert wait_for(lambda: get(pos + ".SEVR", as_string=True) == "NO_ALARM")
        assert "ec0 slave 4 (EL7041): appeared, configured and in OP (1 start-up SDO(s) written)" in ioc.srv.stderr()
        # the axis needs the operator: reset, then enable
        assert get(p + "Y-EnaAct") == 0
        put(p + "Y-RstCmd", 1)
        put(p + "Y-EnaCmd", 1)
        assert wait_for(lambda: get(p + "Y-EnaAct") == 1)
        assert get(p + "Y-ErrId") == 0


def test_power_cycle_of_one_drive_while_the_other_axis_moves(tmp_path, prefix):
    require_binary()
    p = prefix
    with Ioc(tmp_path, prefix) as ioc:
        assert wait_for(lambda: get(p + "m0-Stat-OK") == 1)
        for ax in "XY":
            put(p + ax + "-EnaCmd", 1)
            assert wait_for(lambda: get(p + ax + "-EnaAct") == 1)
        cycles0 = get(p + "m0-ThdCycles")
        put(p + "X-ExeCmd", 0)
        put(p + "X-MtnCmd", 3)
        put(p + "X-TgtPosCmd", 10.0)
        put(p + "X-TgtVelCmd", 5.0)
        put(p + "X-ExeCmd", 1)
        assert wait_for(lambda: get(p + "X-Busy") == 1)
        rc, out = ioc.shell("sim 0 power 4 off")
        assert rc == 0, out
        assert wait_for(lambda: get(p + "m0s004-State", as_string=True) == "LOST", timeout=10)
        assert get(p + "Y-ErrId") == 0x14315
        rc, out = ioc.shell("sim 0 power 4 on")
        assert rc == 0, out
        assert wait_for(lambda: get(p + "m0s004-State", as_string=True) == "OP", timeout=20)
        # X went on to its target without an error while Y's drive was away and came back
        assert wait_for(lambda: get(p + "X-Busy") == 0, timeout=20)
        assert get(p + "X-ErrId") == 0
        # at its target (the at-target window is 0.01; the readback PV follows within a look)
        assert wait_for(lambda: abs(get(p + "X-PosAct") - 10.0) < 0.01, timeout=2), get(p + "X-PosAct")
        assert get(p + "X-EnaAct") == 1
        assert get(p + "m0s002-LostCntr") == 0
        assert get(p + "m0s004-LostCntr") == 1 and get(p + "m0s004-ReconfCntr") == 1
        # the cycle went on throughout (a count; missed slots depend on this VM's wake-ups, see
        # bench/RESULTS.md for the cost of a reconfiguration on the cycle)
        assert get(p + "m0-ThdCycles") > cycles0
        err = ioc.srv.stderr()
        assert "ec0 slave 4 (EL7041): lost (no answer at station 0x1005)" in err, err
        assert "ec0 slave 4 (EL7041): configured again and back in OP (1 start-up SDO(s) written)" in err, err


def test_strict_bus_refuses_to_start_with_a_slave_missing(tmp_path, prefix):
    require_binary()
    ioc = Ioc(tmp_path, prefix, faults='"power 4 off"', strict=True)
    try:
        r = subprocess.run([str(BEAMCTL), "run", str(ioc.cfg), "--ca-port", str(ioc.port)],
                           capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert r.returncode != 0
        assert "4 slave(s) on the bus, but the configuration has a slave at position 4" in r.stderr, r.stderr
    finally:
        release_port(ioc.port)


def test_faults_in_the_ioc_file_are_checked(tmp_path, prefix):
    require_binary()
    ioc = Ioc(tmp_path, prefix, faults='"power 9 off"')
    try:
        r = subprocess.run([str(BEAMCTL), "run", str(ioc.cfg), "--ca-port", str(ioc.port)],
                           capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert r.returncode != 0
        assert "ioc.yaml:6:52:" in r.stderr and "fault 'power 9 off': '9' is not a slave position (0..4)" in r.stderr, r.stderr
    finally:
        release_port(ioc.port)


def test_beamctl_sim_control_socket(tmp_path):
    """`beamctl sim --control SOCK` with an IOC on UDP: the IOC starts with a slave missing (a
    line break injected before it starts), and `beamctl sim fault SOCK repair` brings it in."""
    require_binary()
    sim_yaml = tmp_path / "sim.yaml"
    sim_yaml.write_text("slaves:\n  - {position: 0, type: EK1100}\n  - {position: 1, type: EL2008}\n"
                        "  - {position: 2, type: EL1008}\n")
    sock = str(tmp_path / "sim.sock")
    sim = subprocess.Popen([str(BEAMCTL), "sim", str(sim_yaml), "--udp", "0", "--control", sock],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = [sim.stdout.readline() for _ in range(2)]
        assert lines[0].startswith("control: " + sock), lines
        udp = int(lines[1].split("udp 127.0.0.1:")[1])
        assert oct(os.stat(sock).st_mode & 0o777) == "0o660"  # this user and the socket group (core/local_socket.hpp)
        ok = subprocess.run([str(BEAMCTL), "sim", "fault", sock, "break", "1"], capture_output=True, text=True, timeout=30)
        assert ok.returncode == 0 and ok.stdout == "ok: break 1\n", ok
        bad = subprocess.run([str(BEAMCTL), "sim", "fault", sock, "power", "7", "off"], capture_output=True, text=True,
                             timeout=30)
        assert bad.returncode == 1 and "'7' is not a slave position (0..2)" in bad.stdout, bad
        prefix = "SIMCTL:"
        cfg = tmp_path / "ioc.yaml"
        cfg.write_text(f"""
ioc: {{name: SIMCTL, prefix: "{prefix}"}}
engine: {{rate_hz: 500}}
buses:
  - id: 0
    link: {{type: udp, host: 127.0.0.1, port: {udp}}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL2008}}
      - {{position: 2, type: EL1008}}
""")
        port = acquire_port()
        srv = RunServer(tmp_path, cfg, port).start()
        try:
            assert wait_for(lambda: get(prefix + "m0-SlvOP") == 2)
            assert get(prefix + "m0s002-State", as_string=True) == "MISSING"
            ok = subprocess.run([str(BEAMCTL), "sim", "fault", sock, "repair"], capture_output=True, text=True, timeout=30)
            assert ok.returncode == 0, ok
            assert wait_for(lambda: get(prefix + "m0s002-State", as_string=True) == "OP", timeout=20)
            assert wait_for(lambda: get(prefix + "m0-Stat-OK") == 1)
            # answers 5 ms late (beyond the 1 ms receive time-out at 500 Hz): frames late, counted,
            # no slave reported lost; on time again: the bus is OK without a restart
            late0 = get(prefix + "m0-LateFrames")
            ok = subprocess.run([str(BEAMCTL), "sim", "fault", sock, "delay", "5"], capture_output=True, text=True, timeout=30)
            assert ok.returncode == 0 and ok.stdout == "ok: delay 5\n", ok
            assert wait_for(lambda: get(prefix + "m0-LateFrames") > late0 + 50, timeout=20)
            assert get(prefix + "m0-Stat-OK") == 0
            subprocess.run([str(BEAMCTL), "sim", "fault", sock, "delay", "0"], capture_output=True, text=True, timeout=30)
            assert wait_for(lambda: get(prefix + "m0-Stat-OK") == 1, timeout=20)
            for k in range(3):
                assert get(prefix + f"m0s{k:03d}-LostCntr") == 0
        finally:
            srv.stop()
            srv.kill()
            forget_pvs(prefix)
            release_port(port)
    finally:
        end_process(sim)
    assert not os.path.exists(sock)
    gone = subprocess.run([str(BEAMCTL), "sim", "fault", sock, "repair"], capture_output=True, text=True, timeout=30)
    assert gone.returncode != 0 and "no simulator control socket there" in gone.stderr, gone
