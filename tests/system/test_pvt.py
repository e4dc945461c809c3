"""PVT profile moves through Channel Access (pyepics), with ECMC's documented caput sequence
(ecmccfg examples/PSI/best_practice/motion/pvt/el7041_0052/README.md) on a stepper axis of the
simulated bus: build, execute, readback; a STOP of the motor record in the middle ends the profile
as Failure (never Success); Abort says Abort."""

import shutil
import time
from pathlib import Path

import epics
from epics import ca

from conftest import RunServer, acquire_port, connect, forget_pvs, release_port, require_binary, wait_for

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
      - {{position: 3, type: EL2008}}
axes:
  - {{file: stepper.yaml, macros: {{AX_NAME: Axis1, DRV_SLAVE: 2}}}}
pvt: {{trigger: ec0.s3.binaryOutput01, trigger_duration_s: 0.01}}
"""

PLANT = """
stages:
  - name: x
    drive: s2
    travel: [-60, 60]
    limits:
      forward: {input: s1.binaryInput01, at: 50}
      backward: {input: s1.binaryInput02, at: -50}
"""


def text(name):
    """A CHAR waveform message as text."""
    return epics.caget(name, as_string=True, timeout=5)


def get(name):
    return ca.get(connect(name))


def put(name, value):
    assert ca.put(connect(name), value, wait=True) == 1, name


def start(tmp_path, prefix):
    stepper = (DATA / "stepper.yaml").read_text()
    assert "  motorRecord:\n    enable: ${MR=true}\n" in stepper
    (tmp_path / "stepper.yaml").write_text(stepper.replace(
        "  motorRecord:\n    enable: ${MR=true}\n",
        "  motorRecord:\n    enable: ${MR=true}\n    pvt:\n      npoints: 20\n      nreadback: 20\n"))
    (tmp_path / "plant.yaml").write_text(PLANT)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name=prefix.rstrip(":"), prefix=prefix))
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    srv.start()
    return srv, port


def stop(srv, port, prefix):
    srv.stop()
    srv.kill()
    forget_pvs(prefix)
    release_port(port)


def test_profile_move_as_ecmc_documents_it(tmp_path, prefix):
    require_binary()
    p = prefix
    srv, port = start(tmp_path, p)
    try:
        assert wait_for(lambda: get(p + "m0-Stat-OK") == 1)
        assert text(p + "PVT-BuildMessage") == "Build not executed."
        assert get(p + "PVT-MaxSize") == 20
        # the documented sequence, with times in array mode
        put(p + "PVT-NumPoints", 7)
        put(p + "PVT-NumPulses", 5)
        put(p + "PVT-StartPulses", 2)
        put(p + "PVT-EndPulses", 6)
        put(p + "PVT-MoveMode", 0)
        put(p + "PVT-TimeMode", 1)
        put(p + "PVT-Acceleration", 0.2)
        put(p + "Axis1-PVT-UseAxis", 1)
        put(p + "Axis1-PVT-Positions", [0, 0.5, 1.0, 1.5, 2.0, 1.5, 1.0])
        put(p + "PVT-Times", [0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5])
        assert text(p + "PVT-BuildMessage") == "Time array changed, rebuild required..."
        put(p + "PVT-Build", 1)
        assert epics.caget(p + "PVT-BuildStatus", as_string=True) == "Success", text(p + "PVT-BuildMessage")
        put(p + "PVT-Execute", 1)
        assert wait_for(lambda: get(p + "PVT-ExecuteState") == 2, timeout=10)  # Executing
        assert get(p + "Axis1.DMOV") == 0  # the motor record sees its axis move (ECMC leaves DMOV 1)
        assert wait_for(lambda: get(p + "PVT-ExecuteState") == 0, timeout=20)
        assert epics.caget(p + "PVT-ExecuteStatus", as_string=True) == "Success", text(p + "PVT-ExecuteMessage")
        assert text(p + "PVT-ExecuteMessage") == "Profile done"
        assert get(p + "PVT-NumActualPulses") == 5
        assert get(p + "PVT-SftTrg") == 5
        assert get(p + "PVT-CurrentPoint") == 7
        # readbacks at the 5 pulses: points 2..6 (0.5 .. 1.5), within the stepper's following error
        put(p + "PVT-Readback", 1)
        assert epics.caget(p + "PVT-ReadbackStatus", as_string=True) == "Success"
        rb = list(ca.get(connect(p + "Axis1-PVT-Readbacks")))
        fe = list(ca.get(connect(p + "Axis1-PVT-FollowingErrors")))
        assert len(rb) == 5 and len(fe) == 5, rb
        for got, want in zip(rb, [0.5, 1.0, 1.5, 2.0, 1.5]):
            assert abs(got - want) < 0.05, rb
        assert all(abs(e) < 0.05 for e in fe), fe
        # the motor record ends where the axis stands
        assert wait_for(lambda: get(p + "Axis1.DMOV") == 1)
        assert abs(get(p + "Axis1.RBV") - (1.0 - 1.0 * 0.2 / 2)) < 0.05  # v_last * Ta/2 past the end
    finally:
        stop(srv, port, p)


def test_a_stopped_profile_fails_and_abort_says_abort(tmp_path, prefix):
    require_binary()
    p = prefix
    srv, port = start(tmp_path, p)
    try:
        assert wait_for(lambda: get(p + "m0-Stat-OK") == 1)
        put(p + "PVT-NumPoints", 3)
        put(p + "PVT-NumPulses", 0)
        put(p + "PVT-FixedTime", 2.0)
        put(p + "Axis1-PVT-UseAxis", 1)
        put(p + "Axis1-PVT-Positions", [0, 3, 6])
        put(p + "PVT-Build", 1)
        assert epics.caget(p + "PVT-BuildStatus", as_string=True) == "Success", text(p + "PVT-BuildMessage")
        put(p + "PVT-Execute", 1)
        assert wait_for(lambda: get(p + "PVT-ExecuteState") == 2, timeout=10)
        time.sleep(0.5)
        put(p + "Axis1.STOP", 1)
        assert wait_for(lambda: get(p + "PVT-ExecuteState") == 0, timeout=10)
        assert epics.caget(p + "PVT-ExecuteStatus", as_string=True) == "Failure"
        assert text(p + "PVT-ExecuteMessage").startswith("Profile failed: Axis1 stopped before the end of its path")
        assert get(p + "Axis1.RBV") < 5  # ended short of 6
        # Abort
        put(p + "PVT-Execute", 1)
        assert wait_for(lambda: get(p + "PVT-ExecuteState") == 2, timeout=10)
        put(p + "PVT-Abort", 1)
        assert wait_for(lambda: get(p + "PVT-ExecuteState") == 0, timeout=10)
        assert epics.caget(p + "PVT-ExecuteStatus", as_string=True) == "Abort"
        assert text(p + "PVT-ExecuteMessage") == "Profile aborted."
    finally:
        stop(srv, port, p)
