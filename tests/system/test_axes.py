"""Motion axes behind `beamctl run`, through ECMC's axis PVs with pyepics: enable, an absolute
move with Busy/AtTarget, a velocity move stopped by the forward limit switch (warning, direction
refused, other direction allowed), homing on the low limit and home cam, error reset, and axis
file errors reported by `beamctl check` with file:line:col."""

import shutil
import subprocess
from pathlib import Path

import pytest
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
