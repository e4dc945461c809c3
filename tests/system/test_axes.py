"""Motion axes behind `beamctl run`, through ECMC's axis PVs with pyepics: enable, an absolute
move with Busy/AtTarget, a velocity move stopped by the forward limit switch (warning, direction
refused, other direction allowed), homing on the low limit and home cam, error reset, and axis
file errors reported by `beamctl check` with file:line:col."""

import shutil
import subprocess
from pathlib import Path

import pytest
import epics
from epics import ca

from conftest import BEAMCTL, connect, require_binary, running_ioc, wait_for

DATA = Path(__file__).parent / "data" / "axes"

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim, plant: plant.yaml}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
      - {{position: 2, type: EL7041}}
axes:
  - {{file: stepper.yaml, macros: {{AX_NAME: X, DRV_SLAVE: 2}}}}
"""


def write_config(tmp_path, prefix):
    shutil.copy(DATA / "stepper.yaml", tmp_path / "stepper.yaml")
    shutil.copy(DATA / "plant.yaml", tmp_path / "plant.yaml")
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name=prefix.rstrip(":"), prefix=prefix))
    return cfg


@pytest.fixture
def axis_ioc(tmp_path, prefix):
    files = {"stepper.yaml": DATA / "stepper.yaml", "plant.yaml": DATA / "plant.yaml"}
    with running_ioc(tmp_path, prefix, IOC, files) as srv:
        yield srv, prefix + "X-"


def put(name, value):
    assert ca.put(connect(name), value, wait=True) == 1, name


def get(name):
    return ca.get(connect(name))


def enable(a):
    put(a + "EnaCmd", 1)
    assert wait_for(lambda: get(a + "EnaAct") == 1, timeout=5)


def execute(a, cmd, pos=0.0, vel=None):
    put(a + "ExeCmd", 0)
    put(a + "MtnCmd", cmd)
    put(a + "TgtPosCmd", pos)
    if vel is not None:
        put(a + "TgtVelCmd", vel)
    put(a + "ExeCmd", 1)


def test_absolute_move_through_axis_pvs(axis_ioc):
    _srv, a = axis_ioc
    assert get(a + "EnaAct") == 0
    assert get(a + "Stat") & 0xC0 == 0xC0  # both limits OK
    enable(a)
    execute(a, 3, 5.0)
    assert wait_for(lambda: get(a + "Busy") == 1, timeout=5)
    assert wait_for(lambda: get(a + "Busy") == 0, timeout=10)
    assert wait_for(lambda: get(a + "AtTarget") == 1, timeout=5)
    assert abs(get(a + "PosAct") - 5.0) < 0.01
    assert get(a + "PosSet") == pytest.approx(5.0)
    assert get(a + "ErrId") == 0
    assert get(a + "Stat") & 0x13 == 0x13  # enable, enabled, at target


def test_forward_limit_stops_and_refuses_that_direction(axis_ioc):
    _srv, a = axis_ioc
    enable(a)
    execute(a, 1, 1.0, vel=9.0)  # velocity move forward (TgtPosCmd >= 0)
    assert wait_for(lambda: get(a + "LimFwd") == 0, timeout=15), "forward limit switch at 50 mm"
    assert wait_for(lambda: get(a + "Busy") == 0, timeout=5)
    assert get(a + "WrnId") == 0x114C02
    assert get(a + "ErrId") == 0
    pos = get(a + "PosAct")
    assert 50 < pos < 60
    execute(a, 3, pos + 2)  # further into the switch: refused
    assert wait_for(lambda: get(a + "Busy") == 0, timeout=2)
    assert abs(get(a + "PosAct") - pos) < 0.05
    execute(a, 3, 40.0)  # away from it: allowed
    assert wait_for(lambda: get(a + "AtTarget") == 1 and abs(get(a + "PosAct") - 40) < 0.01, timeout=10)
    assert get(a + "LimFwd") == 1


def test_homing_on_low_limit_and_home_cam(axis_ioc):
    _srv, a = axis_ioc
    enable(a)
    assert get(a + "MtnCmdData") == 14  # the configured sequence (3)
    execute(a, 10)
    assert wait_for(lambda: get(a + "Busy") == 1, timeout=5)
    assert wait_for(lambda: get(a + "LimBwd") == 0, timeout=20), "runs to the low limit first"
    assert wait_for(lambda: get(a + "Busy") == 0 and get(a + "Homed") == 1, timeout=30)
    assert get(a + "ErrId") == 0
    # the cam's edge (stage at -30.5 going forward) now reads -30; the axis stops just past it
    assert -30 < get(a + "PosAct") < -29


def test_errors_latch_until_reset_and_show_in_msgtxt(axis_ioc):
    _srv, a = axis_ioc
    execute(a, 3, 1.0)  # disabled: ERROR_AXIS_NOT_ENABLED, latched
    assert wait_for(lambda: get(a + "ErrId") == 0x14316, timeout=5)
    assert get(a + "Err") == 1
    assert "0x14316" in ca.get(connect(a + "MsgTxt"))
    put(a + "RstCmd", 1)
    assert wait_for(lambda: get(a + "ErrId") == 0, timeout=5)
    enable(a)
    put(a + "MtnCmdData", 0)  # homing sequence 0 is not allowed: 0x14D1A
    execute(a, 10)
    assert wait_for(lambda: get(a + "ErrId") == 0x14D1A, timeout=5)
    execute(a, 3, 1.0)  # refused while the error is latched
    assert wait_for(lambda: get(a + "Busy") == 0, timeout=2)
    assert abs(get(a + "PosAct")) < 0.01
    put(a + "RstCmd", 1)
    assert wait_for(lambda: get(a + "ErrId") == 0 and get(a + "MsgTxt") == "", timeout=5)


def test_axis_file_errors_are_reported_by_check(tmp_path):
    require_binary()
    cfg = write_config(tmp_path, "T:")
    axis = tmp_path / "stepper.yaml"
    axis.write_text(axis.read_text().replace("positionActual01", "positionActual09"))
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1
    assert f"{axis}:" in r.stderr and "no signal 'ec0.s2.positionActual09'" in r.stderr, r.stderr
    axis.write_text((DATA / "stepper.yaml").read_text().replace("velocity: 5", "velocity: -5"))
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1
    assert f"{axis}:" in r.stderr and "velocity" in r.stderr, r.stderr
    shutil.copy(DATA / "stepper.yaml", axis)
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    assert "X-PosAct" in subprocess.run([str(BEAMCTL), "db", str(cfg)], capture_output=True, text=True, timeout=30).stdout


# Records of the IOC's own .db file on the axis's items (issue 12): what ecmccfg's ecmcAxis.db
# writes for PosAct (asynFloat64 on ax1.actpos, I/O Intr), a target and execute of a user's own,
# and a bi on the error id. pyepics sees them follow the axis.
AXIS_DB = r"""
record(ai, "$(P)Pos") {
  field(DTYP, "asynFloat64")
  field(INP, "@asyn(MC_CPU1,0,1)T_SMP_MS=10/TYPE=asynFloat64/ax1.actpos?")
  field(SCAN, "I/O Intr")
  field(PREC, "3")
}
record(ao, "$(P)GoTo") {
  field(DTYP, "beamctl")
  field(OUT, "@ax1.targpos")
  field(FLNK, "$(P)Go")
}
record(bo, "$(P)Go") {
  field(DTYP, "beamctl")
  field(OUT, "@ax1.control.1")
  field(VAL, "1")
}
record(bi, "$(P)InError") {
  field(DTYP, "beamctl")
  field(INP, "@ax1.errorid")
  field(SCAN, "I/O Intr")
  field(ZNAM, "OK")
  field(ONAM, "ERROR")
}
"""


def test_records_of_a_db_file_read_and_command_the_axis_items(tmp_path, prefix):
    text = IOC + "db:\n  - {{file: axis.db, macros: {{P: \"{prefix}\"}}}}\n"
    files = {"stepper.yaml": DATA / "stepper.yaml", "plant.yaml": DATA / "plant.yaml", "axis.db": AXIS_DB}
    with running_ioc(tmp_path, prefix, text, files):
        a = prefix + "X-"
        seen = []
        pos = epics.PV(prefix + "Pos", callback=lambda value=None, **kw: seen.append(value))
        assert pos.wait_for_connection(5)
        put(prefix + "GoTo", 2.0)  # disabled: the axis refuses it with an error
        assert wait_for(lambda: get(prefix + "InError") == 1, timeout=5)
        assert get(a + "ErrId") == 0x14316
        put(a + "RstCmd", 1)
        assert wait_for(lambda: get(prefix + "InError") == 0, timeout=5)
        enable(a)
        put(prefix + "GoTo", 6.0)
        assert wait_for(lambda: get(a + "Busy") == 1, timeout=5)
        assert wait_for(lambda: get(a + "Busy") == 0 and get(a + "AtTarget") == 1, timeout=10)
        # both read the same signal; a stepper may still creep inside its at-target window
        # between two reads, so they agree once a look has updated both
        assert wait_for(lambda: get(prefix + "Pos") == pytest.approx(get(a + "PosAct"), abs=1e-9), timeout=5)
        assert get(prefix + "Pos") == pytest.approx(6.0, abs=0.01)
        assert wait_for(lambda: len(seen) > 5, timeout=5)  # a monitor update per change on the way
        assert seen[-1] == pytest.approx(6.0, abs=0.01)
        pos.disconnect()


def test_enacmd_follows_an_axis_that_something_else_disables(tmp_path, prefix):
    # a PLC, off at start, that disables the axis once and itself
    text = IOC + "plcs:\n  - {{id: 0, file: off.plc, enable: false}}\n"
    files = {"stepper.yaml": DATA / "stepper.yaml", "plant.yaml": DATA / "plant.yaml",
             "off.plc": "ax1.drv.enable := 0;\nplc0.enable := 0;\n"}
    with running_ioc(tmp_path, prefix, text, files):
        a = prefix + "X-"
        seen = []
        ena = epics.PV(a + "EnaCmd", callback=lambda value=None, **kw: seen.append(value))
        assert ena.wait_for_connection(5)
        enable(a)
        assert ena.get() == 1
        put(prefix + "PLC00-EnaCmd", 1)
        assert wait_for(lambda: get(a + "EnaAct") == 0, timeout=5)
        assert wait_for(lambda: ena.get() == 0, timeout=5)  # the command PV reads what the axis does
        assert wait_for(lambda: seen and seen[-1] == 0, timeout=5)  # and says so to monitors
        assert wait_for(lambda: get(prefix + "PLC00-EnaCmd") == 0, timeout=5)  # so does the PLC's
        assert get(a + "EnaAct") == 0  # and nothing enabled it again
        ena.disconnect()
