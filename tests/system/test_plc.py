"""The soft PLC seen by a real EPICS client (pyepics): the demo's virtual slit and mirror axes
moved through their motor records, the PLC PVs (enable, scan time, latched fault), println output, and the
`beamctl plc check` command."""

import math
import subprocess
import time

import epics
from epics import ca

from conftest import BEAMCTL, REPO_ROOT, connect, running_ioc, wait_for




def pos(name):
    return ca.get(connect(f"DEMO:{name}-PosAct"))


def test_virtual_slit_gap_and_centre_move_the_blades(demo):
    # the slit PLC powers the blades and the virtual axes when it starts
    for ax in ("SlitTop", "SlitBottom", "SlitVGap", "SlitVCen"):
        assert wait_for(lambda: ca.get(connect(f"DEMO:{ax}-EnaAct")) == 1, timeout=5), ax
    assert ca.get(connect("DEMO:PLC00-EnaAct")) == 1
    assert ca.get(connect("DEMO:PLC00-Err")) == 0
    assert abs(ca.get(connect("DEMO:PLC00-ScanTime")) - 0.001) < 1e-9
    gap = epics.Motor("DEMO:SlitVGap", timeout=5)
    cen = epics.Motor("DEMO:SlitVCen", timeout=5)
    assert gap.move(4.0, wait=True, timeout=30) == 0
    assert abs(gap.get("RBV") - 4.0) < 0.01
    assert abs(pos("SlitTop") - 2.0) < 0.01 and abs(pos("SlitBottom") + 2.0) < 0.01
    assert abs(cen.get("RBV")) < 0.01
    assert cen.move(1.5, wait=True, timeout=30) == 0
    assert abs(pos("SlitTop") - 3.5) < 0.01 and abs(pos("SlitBottom") + 0.5) < 0.01
    assert abs(gap.get("RBV") - 4.0) < 0.01  # the gap did not drift while the centre moved
    # a blade moved on its own: the virtual readbacks follow it
    top = epics.Motor("DEMO:SlitTop", timeout=5)
    assert top.move(5.5, wait=True, timeout=30) == 0
    assert wait_for(lambda: abs(gap.get("RBV") - 6.0) < 0.01, timeout=5)
    assert wait_for(lambda: abs(cen.get("RBV") - 2.5) < 0.01, timeout=5)
    # the gap's soft limit (30 mm) is the motor record's high limit
    assert gap.move(40.0, wait=True) == -12


def test_virtual_mirror_pitch(demo):
    pitch = epics.Motor("DEMO:MirrorPitch", timeout=5)
    assert wait_for(lambda: ca.get(connect("DEMO:MirrorPitch-EnaAct")) == 1, timeout=5)
    assert pitch.get("EGU") == "mrad"
    assert pitch.move(1.5, wait=True, timeout=30) == 0
    assert abs(pitch.get("RBV") - 1.5) < 0.002
    yui, yuo, yd = pos("MirrorYUI"), pos("MirrorYUO"), pos("MirrorYD")
    assert abs(yui - yuo) < 0.002
    assert abs((yui - yd) - 800 * math.tan(1.5e-3)) < 0.005  # Y jacks 800 mm apart
    for other in ("MirrorYaw", "MirrorRoll", "MirrorX", "MirrorY"):
        assert abs(ca.get(connect(f"DEMO:{other}.RBV"))) < 0.005, other
    assert pitch.move(0.0, wait=True, timeout=30) == 0
    assert abs(pos("MirrorYD")) < 0.01


def test_plc_enable_pv_stops_and_restarts_the_scans(demo):
    scans = connect("DEMO:PLC00-Scans")
    assert wait_for(lambda: ca.get(scans) > 100, timeout=5)
    ca.put(connect("DEMO:PLC00-EnaCmd"), 0, wait=True)
    assert wait_for(lambda: ca.get(connect("DEMO:PLC00-EnaAct")) == 0, timeout=5)
    time.sleep(0.2)
    stopped = ca.get(scans)
    time.sleep(0.3)
    assert ca.get(scans) == stopped
    ca.put(connect("DEMO:PLC00-EnaCmd"), 1, wait=True)
    assert wait_for(lambda: ca.get(scans) > stopped + 50, timeout=5)


IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim, plant: plant.yaml}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
      - {{position: 2, type: EL2008}}
plcs:
  - {{id: 3, file: main.plc, rate_ms: 100}}
"""

MAIN = """
static.n := static.n + 1;
if (plc3.firstscan) { println('hello from', plc3.scantime); };
ec0.s2.binaryOutput02 := static.n % 2;
var v[2] := {1, 2};
if (static.n == 5) { static.bad := v[static.n]; };
"""


def test_plc_pvs_output_and_a_latched_fault(tmp_path, prefix):
    plant = "wiring:\n  - {from: s2.binaryOutput02, to: s1.binaryInput02}\n"
    with running_ioc(tmp_path, prefix, IOC, {"main.plc": MAIN, "plant.yaml": plant}) as srv:
        assert abs(ca.get(connect(prefix + "PLC03-ScanTime")) - 0.1) < 1e-9
        assert wait_for(lambda: any("plc3: hello from" in l and "0.10000" in l for l in srv.stdout_lines), timeout=5), srv.stdout_lines
        # the output written by the PLC toggles at its 10 Hz rate (seen through a wire on BI02)
        bo = connect(prefix + "m0s001-BI02")
        seen = set()
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and len(seen) < 2:
            seen.add(ca.get(bo))
            time.sleep(0.02)
        assert seen == {0, 1}
        # one writer per output: the PLC owns BO02, so CA may only read it; BO01 stays writable
        out = epics.PV(prefix + "m0s002-BO02")
        assert out.wait_for_connection(5)
        assert not out.write_access
        assert epics.caget(prefix + "m0s002-BO02.DESC") == "set by plc3"
        free = epics.PV(prefix + "m0s002-BO01")
        assert free.wait_for_connection(5) and free.write_access
        # scan 5 indexes v[5]: the fault latches in -Err (MAJOR) and is logged with its place
        err = connect(prefix + "PLC03-Err")
        assert wait_for(lambda: ca.get(err) == 1, timeout=5)
        assert ca.get(connect(prefix + "PLC03-Faults")) == 1
        assert epics.caget(prefix + "PLC03-Err.SEVR") == 2
        assert wait_for(lambda: "main.plc:6:" in srv.stderr(), timeout=5), srv.stderr()[-2000:]
        # the scans go on after the fault
        scans = ca.get(connect(prefix + "PLC03-Scans"))
        assert wait_for(lambda: ca.get(connect(prefix + "PLC03-Scans")) > scans, timeout=3)


def run_check(*args):
    return subprocess.run([str(BEAMCTL), "plc", "check", *args], capture_output=True, text=True, timeout=60)


def test_plc_check_command(tmp_path):
    good = tmp_path / "good.plc"
    good.write_text("ax${AX}.traj.extsetpos := ec0.s4.positionActual01 / 1000;\nstatic.x := 1;\n")
    r = run_check("-m", "AX=3", str(good))
    assert r.returncode == 0, r.stderr
    assert "good.plc: OK" in r.stdout
    bad = tmp_path / "bad.plc"
    bad.write_text("static.x := 1;\nax1.enc.actvel := 2;\nstatic.y := nosuch + 1;\n")
    r = run_check(str(bad))
    assert r.returncode == 1
    assert f"{bad}:2:1: 'ax1.enc.actvel' is read-only" in r.stderr
    assert f"{bad}:3:13: unknown name 'nosuch'" in r.stderr
    assert "^" in r.stderr  # the line is shown with a caret
    # against the demo IOC: its axes and entries exist, others do not
    demo = REPO_ROOT / "examples" / "demo" / "ioc.yaml"
    ok = tmp_path / "demo_ok.plc"
    ok.write_text("static.a := ax11.enc.actpos + ec0.s1.binaryInput01;\nec0.s3.binaryOutput01 := 1;\n")
    r = run_check("--ioc", str(demo), str(ok))
    assert r.returncode == 0, r.stderr
    nok = tmp_path / "demo_bad.plc"
    nok.write_text("static.a := ax99.enc.actpos;\nec0.s1.binaryInput01 := 1;\n")
    r = run_check("--ioc", str(demo), str(nok))
    assert r.returncode == 1
    assert "no axis 99" in r.stderr
    assert "'ec0.s1.binaryInput01' is read-only" in r.stderr
    # the shipped PLC library compiles
    r = run_check("-I", str(REPO_ROOT / "examples" / "plc_lib"), str(REPO_ROOT / "examples" / "demo" / "plc" / "slit.plc"))
    assert r.returncode == 0, r.stderr


DS_IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim}}
    slaves:
      - {{position: 0, type: EK1100}}
storages:
  - {{id: 0, size: 5, type: normal, sample_rate_ms: 10, desc: "counter samples"}}
  - {{id: 1, size: 4, type: ring, capacity: 8}}
plcs:
  - {{id: 0, file: ds.plc, rate_ms: 10}}
"""

# ecmccfg's best-practice data storage PLC, in spirit: fill ds0, push when a trigger rises;
# ds1 is a ring of the last 4 values, published only on ds_push_asyn
DS_PLC = """
static.n += 1;
ds_append_data(0, static.n);
ds1.append := static.n * 10;
if (static.n % 20 == 0) { ds_push_asyn(1); };
static.started := epics_get_started();
if (static.started and not(static.was)) { println('epics started at scan', static.n); };
static.was := static.started;
"""


def test_data_storage_pvs(tmp_path, prefix):
    with running_ioc(tmp_path, prefix, DS_IOC, {"ds.plc": DS_PLC}) as srv:
        p = prefix + "DS00-"
        assert epics.caget(p + "Desc") == "counter samples"
        assert epics.caget(p + "Type", as_string=True) == "Normal"
        assert epics.caget(p + "DataAct.NELM") == 5
        full = connect(p + "Full")
        assert wait_for(lambda: ca.get(full) == 1, timeout=5)
        data = epics.caget(p + "DataAct")
        assert list(data) == [1, 2, 3, 4, 5]  # a normal buffer keeps its first values
        assert epics.caget(p + "DataIdAct") == 5
        assert epics.caget(p + "Stat") == 1  # bit 0 full, type 0
        # the operator clears it: it fills again with newer values
        assert epics.caput(p + "ClrCmd", 1, wait=True) == 1
        assert wait_for(lambda: epics.caget(p + "DataAct")[0] > 5, timeout=5)
        # the ring: capacity 8 for NELM, the size 4 values; pushed every 20 scans
        r = prefix + "DS01-"
        assert epics.caget(r + "DataAct.NELM") == 8
        assert epics.caget(r + "Type", as_string=True) == "Ring"
        assert wait_for(lambda: epics.caget(r + "Count") == 4, timeout=5)
        vals = epics.caget(r + "DataAct")
        assert len(vals) == 4 and sorted(vals)[-1] - sorted(vals)[0] == 30  # the last four: n*10
        assert epics.caget(r + "Err") == 0
        # epics_get_started() turned 1 once the IOC ran
        assert wait_for(lambda: any("epics started at scan" in l for l in srv.stdout_lines), timeout=5)
        # the DataSet write: values from index 0 (the cycle keeps appending after them)
        st = prefix + "DS00-"
        assert epics.caput(st + "DataSet", [100, 200], wait=True) == 1
        assert wait_for(lambda: list(epics.caget(st + "DataAct"))[:2] == [100, 200], timeout=5)
        assert wait_for(lambda: epics.caget(st + "Full") == 1, timeout=5)
        assert epics.caget(st + "DataAct")[2] > 5  # the PLC's appends went on after them


def test_data_storage_config_errors(tmp_path):
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text("ioc: {name: X}\nstorages:\n  - {id: 0, size: 10, type: circular}\n  - {id: 0, size: 5, capacity: 2}\n"
                   "plcs:\n  - {id: 0, file: p.plc}\n")
    (tmp_path / "p.plc").write_text("ds3.append := 1;\n")
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0
    out = r.stdout + r.stderr
    assert "ioc.yaml:3:" in out and "'circular' is not a buffer type" in out, out
    assert "data storage id 0 used twice" in out, out
    assert "2 is less than the size 5" in out, out


AXIS_PLC_IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim}}
    slaves:
      - {{position: 0, type: EK1100}}
axes:
  - {{file: vx.yaml}}
"""

VX = """
axis: {id: 4, type: virtual}
epics: {name: VX, precision: 3, unit: mm}
encoder: {numerator: 1, denominator: 1, type: 1, bits: 32, source: 1}
trajectory: {axis: {velocity: 1, acceleration: 5}}
input:
  limit: {forward: ec0.s0.ONE.0, backward: ec0.s0.ONE.0}
  home: ec0.s0.ONE.0
  interlock: ec0.s0.ONE.0
monitoring:
  lag: {enable: false, tolerance: 1, time: 100}
  target: {enable: true, tolerance: 0.01, time: 10}
softlimits: {enable: true, forward: 10, forwardEnable: true, backward: -10, backwardEnable: true}
plc:
  enable: true
  code:
    - "static.n += 1;"
    - "ax4.enc.actpos := ax4.traj.setpos;"
    - "if (static.n == 300) { ax4.mon.highsoftlim := 12.5; ax4.mon.lowsoftlim := -3; };"
    - "if (static.n == 500) { ax4.plc.enable := 0; };"
"""


def test_axis_plc_pvs(tmp_path, prefix):
    """An axis PLC is served as ecmccfg's ecmcAxis.db does, under the axis's name."""
    with running_ioc(tmp_path, prefix, AXIS_PLC_IOC, {"vx.yaml": VX}):
        p = prefix + "VX-PLC-"
        assert abs(ca.get(connect(p + "ScanTime")) - 0.001) < 1e-9
        assert ca.get(connect(p + "FirstScan")) == 0  # long past its first scan once the IOC serves
        assert wait_for(lambda: ca.get(connect(p + "EnaCmd-RB")) == 0, timeout=5)  # it disabled itself
        scans = ca.get(connect(p + "Scans"))
        assert 490 <= scans <= 510, scans
        assert ca.get(connect(p + "Err")) == 0
        epics.caput(p + "EnaCmd", 1, wait=True)
        assert wait_for(lambda: ca.get(connect(p + "Scans")) > scans + 100, timeout=5)
        # soft limits moved by PLC code (as ecmccfg's slit include does every scan): the motor
        # record's limits follow them
        assert wait_for(lambda: epics.caget(prefix + "VX.DHLM") == 12.5, timeout=5), epics.caget(prefix + "VX.DHLM")
        assert epics.caget(prefix + "VX.DLLM") == -3 and epics.caget(prefix + "VX.HLM") == 12.5


STRICT_IOC = """
ioc: {{name: strict, prefix: "STRICT:"}}
engine: {{rate_hz: 1000}}
plcs:
  - {{id: 0, file: main.plc, strict: {strict}}}
"""


def test_strict_ecmc_mode(tmp_path):
    """`plc check --strict` and `strict: true` report what ECMC's ExprTk refuses, with the place
    and the ECMC spelling; without them the same file compiles (issue 18)."""
    plc = tmp_path / "main.plc"
    plc.write_text("static.x := 1;;\n{ var a := 2; static.y := a; };\nfor (; static.x < 3; static.x += 1) { static.y += 1; };\n")
    r = run_check(str(plc))
    assert r.returncode == 0, r.stderr
    r = run_check("--strict", str(plc))
    assert r.returncode == 1
    assert f"{plc}:1:15: strict ECMC: ExprTk refuses an empty statement" in r.stderr, r.stderr
    assert f"{plc}:2:1: strict ECMC: ExprTk refuses a bare '{{ ...; }}' block" in r.stderr, r.stderr
    assert "ECMC spelling: '~{ ... }'" in r.stderr
    assert f"{plc}:3:6: strict ECMC: ExprTk refuses 'for' without an initialiser" in r.stderr, r.stderr
    # the ECMC spellings pass
    plc.write_text("static.x := 1;\n~{ var a := 2; static.y := a; };\nwhile (static.x < 3) { static.x += 1; };\n")
    r = run_check("--strict", str(plc))
    assert r.returncode == 0, r.stderr
    # in the IOC file: strict: true makes the same constructs errors when the IOC is built
    plc.write_text("static.x := 1;;\n")
    for strict, ok in (("false", True), ("true", False)):
        cfg = tmp_path / "ioc.yaml"
        cfg.write_text(STRICT_IOC.format(strict=strict))
        r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=60)
        assert (r.returncode == 0) == ok, r.stdout + r.stderr
        if not ok:
            assert "main.plc:1:15: strict ECMC: ExprTk refuses an empty statement" in r.stdout + r.stderr
    # the shipped kinematics pass strict mode
    for f in ("mirror.plc", "mirror_matrix.plc", "spiral.plc", "slit.plc"):
        r = run_check("--strict", "-I", str(REPO_ROOT / "examples" / "plc_lib"), str(REPO_ROOT / "examples" / "kinematics" / f))
        assert r.returncode == 0, r.stderr
