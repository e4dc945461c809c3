"""The simulator's plant behind `beamctl run`, seen through entry PVs with pyepics: a stepper
stage driven into its limit switch and back, a CiA402 servo enabled through its state machine
on a default stage (no plant entry), an analog sensor that follows a stage, a signal generator,
and plant errors reported by `beamctl check` with file:line:col."""

import subprocess

import pytest
from epics import ca

from conftest import BEAMCTL, connect, require_binary, running_ioc, wait_for

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
      - {{position: 3, type: EL3104}}
      - {{position: 4, type: EL7211}}
"""

PLANT = """
stages:
  - name: x
    drive: s2
    travel: [-10, 10]
    start: 4
    limits:
      forward: {input: s1.binaryInput01, at: 5}
      backward: {input: s1.binaryInput02, at: -5}
    home: {input: s1.binaryInput03, at: 0, width: 1}
signals:
  - {to: s3.analogInput01, stage: x, gain: 1}
  - {to: s3.analogInput02, shape: sine, amplitude: 4, frequency: 2}
"""


@pytest.fixture
def plant_ioc(tmp_path, prefix):
    with running_ioc(tmp_path, prefix, IOC, {"plant.yaml": PLANT}) as srv:
        yield srv, prefix


def put(name, value):
    assert ca.put(connect(name), value, wait=True) == 1, name


def get(name):
    return ca.get(connect(name))


def test_stepper_stage_reaches_its_limit_switch_and_returns(plant_ioc):
    _srv, p = plant_ioc
    s = p + "m0s002-"
    assert get(p + "m0s001-BI01") == 1  # normally closed: 1 = not at the limit
    assert get(p + "m0s001-BI03") == 0  # not on the home cam (at 4 mm)
    assert get(s + "driveStatus01") & 0x3 == 0x1  # ready to enable, not enabled
    start = get(s + "positionActual01")
    put(s + "velocitySetpoint01", 32767)  # 10 mm/s: enables nothing yet
    put(s + "driveControl01", 1)
    assert wait_for(lambda: get(s + "driveStatus01") & 0x12 == 0x12, timeout=5)  # ready + moving positive
    assert wait_for(lambda: get(p + "m0s001-BI01") == 0, timeout=10), "forward limit switch at 5 mm"
    assert get(p + "m0s001-BI02") == 1
    assert get(s + "positionActual01") != start
    put(s + "velocitySetpoint01", -32767)
    assert wait_for(lambda: get(p + "m0s001-BI01") == 1, timeout=10)
    assert wait_for(lambda: get(p + "m0s001-BI03") == 1, timeout=10), "home cam at 0 mm"
    put(s + "driveControl01", 0)  # disabled: the status says so and the stage coasts to rest
    assert wait_for(lambda: get(s + "driveStatus01") & 0x2 == 0, timeout=5)


def test_servo_cia402_state_machine_through_pvs(plant_ioc):
    _srv, p = plant_ioc
    s = p + "m0s004-"
    assert wait_for(lambda: get(s + "driveStatus01") & 0x6F == 0x40, timeout=5)  # switch on disabled
    for cw, state in [(0x06, 0x21), (0x07, 0x23), (0x0F, 0x27)]:
        put(s + "driveControl01", cw)
        assert wait_for(lambda: get(s + "driveStatus01") & 0x6F == state, timeout=5), hex(cw)
    pos0 = get(s + "positionActual01")
    put(s + "velocitySetpoint01", 268435)  # 1 rev/s on the default stage
    assert wait_for(lambda: abs(get(s + "velocityActual01") - 268435) < 100, timeout=5)
    assert wait_for(lambda: get(s + "positionActual01") != pos0, timeout=5)
    put(s + "driveControl01", 0x0B)  # quick stop: ramps down, then switch on disabled
    assert wait_for(lambda: get(s + "driveStatus01") & 0x6F == 0x40, timeout=10)
    assert wait_for(lambda: get(s + "velocityActual01") == 0, timeout=5)


def test_analog_sensor_follows_the_stage_and_generator_runs(plant_ioc):
    _srv, p = plant_ioc
    ai1 = p + "m0s003-AI01"
    assert wait_for(lambda: abs(get(ai1) - 4 * 3276.7) <= 1, timeout=5)  # 1 V/mm at 4 mm
    put(p + "m0s002-velocitySetpoint01", -32767)
    put(p + "m0s002-driveControl01", 1)
    assert wait_for(lambda: get(ai1) < 0, timeout=10)  # crossed 0 mm
    seen = set()
    assert wait_for(lambda: seen.add(get(p + "m0s003-AI02")) or len(seen) > 5, timeout=5)
    assert all(abs(v) <= 4 * 3276.7 + 1 for v in seen)


def test_plant_errors_are_reported_by_check(tmp_path):
    require_binary()
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name="T", prefix="T:"))
    plant = tmp_path / "plant.yaml"
    plant.write_text(PLANT.replace("drive: s2", "drive: s3"))
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1
    assert f"{plant}:4:" in r.stderr and "EL3104, not a drive" in r.stderr, r.stderr
    plant.write_text(PLANT + "  - {to: s3.analogInput01, shape: sine}\n")
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1
    assert f"{plant}:14:" in r.stderr and "already driven" in r.stderr, r.stderr
    plant.write_text(PLANT)
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
