"""The motor record of an axis ($(P)X), driven by pyepics' epics.Motor and by the sequence
ophyd's EpicsMotor uses: moves with wait, soft limits refusing a move, set_position, tweak, stop,
homing, and the DMOV 1->0->1 edge with RBV at NO_ALARM after a good move."""

import subprocess
import time

import epics
import pytest
from epics import ca

from conftest import BEAMCTL, connect, running_ioc, wait_for
from test_axes import DATA

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
  - {{file: stepper.yaml, macros: {{AX_NAME: X, DRV_SLAVE: 2, SOFT: "true"}}}}
"""

# ophyd EpicsMotor's 19 components (all non-lazy)
OPHYD_FIELDS = ["RBV", "VAL", "OFF", "DIR", "FOFF", "SET", "VELO", "ACCL", "EGU", "MOVN", "DMOV", "HLS", "LLS",
                "HLM", "LLM", "TDIR", "STOP", "HOMF", "HOMR"]


@pytest.fixture
def motor(tmp_path, prefix):
    files = {"stepper.yaml": DATA / "stepper.yaml", "plant.yaml": DATA / "plant.yaml"}
    with running_ioc(tmp_path, prefix, IOC, files):
        m = epics.Motor(prefix + "X", timeout=5)
        m.put("CNEN", 1, wait=True)
        assert wait_for(lambda: ca.get(connect(prefix + "X-EnaAct")) == 1, timeout=5)
        yield m, prefix


def test_move_with_wait_and_limits(motor):
    m, p = motor
    assert m.get("RTYP") == "motor"
    assert (m.get("HLM"), m.get("LLM")) == (45, -45)  # the axis's soft limits
    t0 = time.monotonic()
    assert m.move(5, wait=True, timeout=20) == 0
    assert time.monotonic() - t0 > 0.9  # 5 mm at 5 mm/s takes more than a second
    assert m.get("DMOV") == 1
    assert abs(m.get("RBV") - 5) < 0.01
    assert abs(ca.get(connect(p + "X-PosAct")) - 5) < 0.01
    assert m.move(50, wait=True) == -12  # beyond HLM: refused by pyepics, nothing written
    assert m.move(2, relative=True, wait=True, timeout=20) == 0
    assert abs(m.get("RBV") - 7) < 0.01
    assert m.move(-3, dial=True, wait=True, timeout=20) == 0
    assert abs(m.get("DRBV") + 3) < 0.01


def test_soft_limit_violation_sets_lvio_and_moves_nothing(motor):
    m, _p = motor
    assert m.move(60, wait=True, ignore_limits=True, timeout=10) == -4  # LVIO after the put
    assert m.get("LVIO") == 1
    assert abs(m.get("RBV")) < 0.01


def test_set_position_tweak_stop(motor):
    m, p = motor
    m.set_position(10)  # SET=1, VAL=10, SET=0 (plain puts in order)
    assert wait_for(lambda: abs(m.get("RBV") - 10) < 0.01, timeout=5)
    m.put("TWV", 0.5)
    m.tweak(direction="forward", wait=True)
    assert abs(m.get("RBV") - 10.5) < 0.01
    m.move(30, wait=False)
    assert wait_for(lambda: m.get("MOVN") == 1, timeout=5)
    time.sleep(0.5)
    m.stop()
    assert wait_for(lambda: m.get("DMOV") == 1, timeout=10)
    rbv = m.get("RBV")
    assert 11 < rbv < 29  # stopped on the way
    assert abs(m.get("VAL") - rbv) < 0.01  # after a stop VAL = RBV


def test_homing_from_the_motor_record(motor):
    m, p = motor
    m.put("HOMR", 1)
    assert wait_for(lambda: m.get("DMOV") == 0, timeout=5)
    assert wait_for(lambda: m.get("DMOV") == 1, timeout=40)
    assert ca.get(connect(p + "X-Homed")) == 1
    assert int(m.get("MSTA")) & (1 << 14)  # HOMED
    assert -30.1 < m.get("DRBV") < -29  # the home cam's edge reads -30


def test_ophyd_epics_motor_sequence(motor):
    """What ophyd's EpicsMotor.move does: all 19 fields connect; VAL's ctrl limits; a put to VAL
    without callback; the move is done on the DMOV 1->0->1 edge; RBV severity must be NO_ALARM."""
    m, p = motor
    pvs = {f: epics.PV(f"{p}X.{f}", form="ctrl") for f in OPHYD_FIELDS}
    assert all(pv.wait_for_connection(timeout=5) for pv in pvs.values())
    val = pvs["VAL"]
    ctrl = val.get_ctrlvars()
    assert (ctrl["lower_ctrl_limit"], ctrl["upper_ctrl_limit"]) == (-45, 45)
    assert pvs["DMOV"].get() == 1
    dmov = []
    pvs["DMOV"].add_callback(lambda value=None, **kw: dmov.append(value))
    val.put(3.0, wait=False)
    assert wait_for(lambda: dmov[-2:] == [0, 1], timeout=20), dmov
    rbv = epics.PV(f"{p}X.RBV", form="time")
    assert rbv.wait_for_connection(timeout=5)
    rbv.get()
    assert rbv.severity == 0
    assert abs(rbv.value - 3) < 0.01
    assert pvs["TDIR"].get() == 1 and pvs["HLS"].get() == 0 and pvs["LLS"].get() == 0
    # a null move still pulses DMOV
    n = len(dmov)
    val.put(3.0, wait=False)
    assert wait_for(lambda: len(dmov) >= n + 2 and dmov[-2:] == [0, 1], timeout=10), dmov


def test_soft_limit_interlock_from_ecmc_pvs_sets_problem(motor):
    """ECMC acceptance 14: a move commanded past the soft limit (through the axis PVs, which the
    motor record does not see) is refused with warning 0x114D00 and the record shows PROBLEM."""
    m, p = motor
    for name, value in [("X-MtnCmd", 3), ("X-TgtPosCmd", 60), ("X-ExeCmd", 1)]:
        assert ca.put(connect(p + name), value, wait=True) == 1
    assert wait_for(lambda: ca.get(connect(p + "X-WrnId")) == 0x114D00, timeout=5)
    assert wait_for(lambda: int(m.get("MSTA")) & (1 << 9), timeout=5)  # PROBLEM
    assert abs(m.get("RBV")) < 0.01
    assert m.move(1.0, wait=True, timeout=20) == 0  # a valid move clears it
    assert wait_for(lambda: not int(m.get("MSTA")) & (1 << 9), timeout=5)


def auto_enable_ioc(tmp_path, prefix, enabled_bit=1):
    """The stepper with ECMC's axis.autoEnable (enable within 2 s, disable after 1 s idle)."""
    axis = (DATA / "stepper.yaml").read_text()
    axis = axis.replace("axis:\n  id: 1\n", "axis:\n  id: 1\n  autoEnable:\n    enableTimeout: 2\n"
                        "    disableTimeout: 1\n", 1)
    axis = axis.replace("  enabled: 1\n", f"  enabled: {enabled_bit}\n", 1)
    assert "autoEnable" in axis and f"enabled: {enabled_bit}" in axis
    (tmp_path / "auto.yaml").write_text(axis)
    files = {"plant.yaml": DATA / "plant.yaml"}
    return running_ioc(tmp_path, prefix, IOC.replace("stepper.yaml", "auto.yaml"), files)


def test_auto_enable_axis_moves_from_cnen_0_and_disables_after_the_idle_time(tmp_path, prefix):
    """Issue 13: Motor.move(wait=True) on an autoEnable axis with CNEN=0 enables it, moves, ends
    in success, and the axis disables itself disableTimeout after it is idle (CNEN follows)."""
    with auto_enable_ioc(tmp_path, prefix):
        m = epics.Motor(prefix + "X", timeout=5)
        assert m.get("CNEN") == 0
        assert ca.get(connect(prefix + "X-EnaAct")) == 0
        cnen = []
        mon = epics.PV(prefix + "X.CNEN", auto_monitor=True, callback=lambda value=None, **kw: cnen.append(value))
        assert mon.wait_for_connection(5)
        assert m.move(3, wait=True, timeout=30) == 0
        assert abs(m.get("RBV") - 3) < 0.01
        assert m.get("DMOV") == 1
        assert not int(m.get("MSTA")) & (1 << 9)  # no PROBLEM
        assert ca.get(connect(prefix + "X.SEVR")) == 0
        # disabled by itself once idle for 1 s; the record's CNEN followed it up and down
        assert wait_for(lambda: ca.get(connect(prefix + "X-EnaAct")) == 0, timeout=10)
        assert wait_for(lambda: m.get("CNEN") == 0, timeout=5)
        assert wait_for(lambda: cnen[-2:] == [1, 0], timeout=5), cnen
        assert ca.get(connect(prefix + "X-ErrId")) == 0
        # and it moves again from there
        assert m.move(1, wait=True, timeout=30) == 0
        assert abs(m.get("RBV") - 1) < 0.01
        mon.disconnect()


def test_auto_enable_timeout_fails_the_move(tmp_path, prefix):
    """A drive that never reports enabled: after enableTimeout the axis latches 0x1432F, the move
    fails (PROBLEM, alarm, failed put-callback) and nothing moved."""
    import ca_raw
    with auto_enable_ioc(tmp_path, prefix, enabled_bit=7) as ioc:
        m = epics.Motor(prefix + "X", timeout=5)
        m.move(3, wait=True, timeout=30)  # pyepics looks only at LVIO/HLS/LLS: check the record
        assert wait_for(lambda: ca.get(connect(prefix + "X-ErrId")) == 0x1432F, timeout=10)
        assert int(m.get("MSTA")) & (1 << 9)  # PROBLEM
        assert ca.get(connect(prefix + "X.SEVR")) != 0
        assert abs(m.get("RBV")) < 0.01
        assert m.get("CNEN") == 0
        # the put-callback of a move fails (ECA_PUTFAIL), as ophyd and caput -c see it
        assert ca.put(connect(prefix + "X-RstCmd"), 1, wait=True) == 1
        with ca_raw.Circuit("127.0.0.1", ioc.port) as c:
            ch = c.create(prefix + "X")
            assert c.write_notify(ch, [2.0], dtype=ca_raw.DOUBLE, timeout=30).p1 == ca_raw.ECA_PUTFAIL


ASYN_IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim, plant: plant.yaml}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
      - {{position: 2, type: EL7041}}
      - {{position: 3, type: EL2008}}
axes:
  - {{file: stepper.yaml, macros: {{AX_NAME: X, DRV_SLAVE: 2, MR: "false"}}}}
plcs:
  - {{id: 0, file: kp.plc}}
db:
  - file: asyn_motor_like.db
    macros: {{P: "{prefix}", M: "m1", DESC: "stage x", DTYP: asynMotor, PORT: MC_CPU1, ADDR: 1, VELO: 4, ACCL: 0.2,
              MRES: 0.0001, EGU: mm, DHLM: 40, DLLM: -40}}
"""

# the controller's Kp, seen on two outputs (PLC code reads ax1.ctrl.kp; records do not)
KP_PLC = "ec0.s3.binaryOutput01 := ax1.ctrl.kp == 10;\nec0.s3.binaryOutput02 := ax1.ctrl.kp == 20;\n"



def test_synapps_asyn_motor_db_drives_the_axis(tmp_path, prefix):
    """The stock synApps asyn_motor.db shape (DTYP asynMotor, @asyn(MC_CPU1,1)) loads as it is
    and drives axis 1, as ECMC's motor driver does; its speed fields in rev/s, the enable record
    on DISP, PCOF..DCOF, SYNC and STUP act."""
    files = {"stepper.yaml": DATA / "stepper.yaml", "plant.yaml": DATA / "plant.yaml",
             "asyn_motor_like.db": DATA.parent / "db" / "asyn_motor_like.db", "kp.plc": KP_PLC}
    with running_ioc(tmp_path, prefix, ASYN_IOC, files):
        assert not epics.PV(prefix + "X").wait_for_connection(1)  # MR false: no motor record of its own
        m = epics.Motor(prefix + "m1", timeout=5)
        assert m.get("DESC") == "stage x"
        m.put("CNEN", 1, wait=True)
        assert wait_for(lambda: ca.get(connect(prefix + "X-EnaAct")) == 1, timeout=5)
        assert m.move(3, wait=True, timeout=20) == 0
        assert abs(m.get("RBV") - 3) < 0.01
        assert abs(ca.get(connect(prefix + "X-PosAct")) - 3) < 0.01  # the engine's axis 1 moved
        # the driver's copies: resolution, direction, offset
        assert wait_for(lambda: abs(ca.get(connect(prefix + "m1Resolution")) - 0.0001) < 1e-9, timeout=5)
        # S [rev/s] = VELO / UREV; writing S sets VELO
        urev = m.get("UREV")
        assert abs(m.get("S") - 4 / urev) < 1e-9
        epics.caput(prefix + "m1.S", 5 / urev, wait=True)
        assert abs(m.get("VELO") - 5) < 1e-6
        # ACCS [EGU/s^2] and ACCL [s] follow each other
        epics.caput(prefix + "m1.ACCS", 50, wait=True)
        assert abs(m.get("ACCL") - 0.1) < 1e-9 and m.get("ACCU") == 1
        # PCOF is the controller's Kp / 100 (ECMC's driver); above 0.99 it is refused
        kp10, kp20 = connect(prefix + "m0s003-BO01"), connect(prefix + "m0s003-BO02")
        assert wait_for(lambda: ca.get(kp10) == 1, timeout=5)  # PCOF 0.1 at init: Kp 10
        assert epics.caput(prefix + "m1.PCOF", 0.2, wait=True) == 1
        assert wait_for(lambda: ca.get(kp20) == 1, timeout=5)
        epics.caput(prefix + "m1.PCOF", 1.5, wait=True)
        assert abs(m.get("PCOF") - 0.2) < 1e-9  # refused: the old value stays
        time.sleep(0.2)
        assert ca.get(kp20) == 1
        # the enable record (asyn_motor.db's _able on DISP): disabled, a put is refused
        epics.caput(prefix + "m1_able", 1, wait=True)
        assert m.get("DISP") == 1
        epics.caput(prefix + "m1.VAL", 1, wait=True, timeout=5)
        time.sleep(0.3)
        assert abs(m.get("VAL") - 3) < 0.01 and abs(m.get("RBV") - 3) < 0.01  # refused: DISP
        epics.caput(prefix + "m1_able", 0, wait=True)
        assert m.move(1, wait=True, timeout=20) == 0
        # SYNC and STUP return to 0 and leave the record idle at its readback
        epics.caput(prefix + "m1.SYNC", 1, wait=True)
        assert m.get("SYNC") == 0 and abs(m.get("VAL") - m.get("RBV")) < 0.01
        epics.caput(prefix + "m1.STUP", 1, wait=True)
        assert m.get("STUP", as_string=True) == "OFF"
        # HIGH with HSV: the readback beyond it is a HIGH alarm
        epics.caput(prefix + "m1.HIGH", 0.5, wait=True)
        epics.caput(prefix + "m1.HSV", "MINOR", wait=True)
        assert wait_for(lambda: epics.caget(prefix + "m1.SEVR") == 1, timeout=5)


def test_asyn_motor_db_naming_a_missing_axis_is_an_error(tmp_path, prefix):
    files = {"stepper.yaml": DATA / "stepper.yaml", "plant.yaml": DATA / "plant.yaml",
             "asyn_motor_like.db": DATA.parent / "db" / "asyn_motor_like.db"}
    for name, content in files.items():
        (tmp_path / name).write_bytes(content.read_bytes())
    (tmp_path / "kp.plc").write_text(KP_PLC)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(ASYN_IOC.format(name="T", prefix="T:").replace("ADDR: 1", "ADDR: 7"))
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0
    assert "record T:m1: OUT '@asyn(MC_CPU1,7)': no axis 7 (axes: 1)" in r.stdout + r.stderr, r.stdout + r.stderr
