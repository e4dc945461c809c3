"""The demo beamline (examples/demo/ioc.yaml, what `bash build.sh demo` runs): it loads, reaches
OP with all 26 terminals, and its real axes work through their motor records: a slit blade homes and
moves, the absolute-encoder sample axis is referenced at start, the soft records are served."""


import epics
from epics import ca

from conftest import put_status, connect, wait_for

AXES = ["SlitTop", "SlitBottom", "SlitLeft", "SlitRight", "SampleX", "SampleY"]




def test_demo_runs_twenty_six_terminals_and_its_axes(demo):
    assert ca.get(connect("DEMO:m0-SlvCntr")) == 26
    for pos in range(26):
        assert wait_for(lambda: ca.get(connect(f"DEMO:m0s{pos:03d}-Operational")) == 1, timeout=5)
    for ax in AXES:
        assert ca.get(connect(f"DEMO:{ax}.RTYP")) == "motor"
        assert ca.get(connect(f"DEMO:{ax}-ErrId")) == 0
    assert ca.get(connect("DEMO:SampleX-Homed")) == 1  # absolute encoder
    assert ca.get(connect("DEMO:SlitTop-Homed")) == 0
    assert abs(ca.get(connect("DEMO:SampleX-PosAct")) - 1.5) < 0.01  # the stage starts at 1.5 mm


def test_demo_slit_blade_homes_and_moves(demo):
    m = epics.Motor("DEMO:SlitTop", timeout=5)
    m.put("CNEN", 1, wait=True)
    assert wait_for(lambda: ca.get(connect("DEMO:SlitTop-EnaAct")) == 1, timeout=5)
    m.put("HOMF", 1)
    assert wait_for(lambda: m.get("DMOV") == 0, timeout=5)
    assert wait_for(lambda: m.get("DMOV") == 1, timeout=60)
    assert ca.get(connect("DEMO:SlitTop-Homed")) == 1
    assert m.move(4.0, wait=True, timeout=30) == 0
    assert abs(m.get("RBV") - 4.0) < 0.01
    # the LVDT on the top blade reads 0.1 V/mm of the blade's real position
    lvdt = ca.get(connect("DEMO:m0s005-AI02")) / 3276.7
    assert abs(lvdt - 0.4) < 0.01
    assert m.move(40.0, wait=True) == -12  # beyond the soft limit (17 mm)


def test_demo_sample_y_reads_both_encoders(demo):
    m = epics.Motor("DEMO:SampleY", timeout=5)
    m.put("CNEN", 1, wait=True)
    assert m.move(2.0, wait=True, timeout=20) == 0
    enc1 = ca.get(connect("DEMO:SampleY-Enc01-PosAct"))  # EL5101 scale (primary)
    enc2 = ca.get(connect("DEMO:SampleY-Enc02-PosAct"))  # the stepper's encoder input
    assert abs(enc1 - 2.0) < 0.01
    assert abs(enc2 - 2.0) < 0.01
    # the primary encoder is the axis's readback (read again together: it may creep in the window)
    assert wait_for(lambda: ca.get(connect("DEMO:SampleY-PosAct")) == ca.get(connect("DEMO:SampleY-Enc01-PosAct")), timeout=5)


def test_demo_beam_on_the_quad_electrometer_and_the_loop_that_holds_it(demo):
    """The simulated beam lands on the quadrant diode behind DEMO:QE1: (quadEM's PVs): the source's
    7 Hz vibration is PosY's sigma, a mirror pitch of 1 urad moves the spot ~20 um (2 x 10 m x
    1 urad), and DEMO:epidFast1 brings it back to 0 with the piezo and takes out most of the
    vibration: the residual is served as PosY:SigmaValue_RBV."""
    p = "DEMO:QE1:"
    assert epics.caput(p + "AveragingTime", 1.0, wait=True) == 1  # 7 periods of the vibration

    def reading():
        n = ca.get(connect(p + "NumAcquired"))
        assert wait_for(lambda: ca.get(connect(p + "NumAcquired")) >= n + 2, timeout=10)
        return ca.get(connect(p + "PosY:MeanValue_RBV")), ca.get(connect(p + "PosY:SigmaValue_RBV"))
    y0, open_rms = reading()
    assert 5 < open_rms < 9, open_rms  # 10 um amplitude: 7.1 um rms
    # the camera DEMO:cam1: (5 um pixels) at the same plane: exposures of two periods of the
    # vibration, the gain down below saturation, the centroid over the spot (not the dark level)
    for pv, v in (("cam1:AcquireTime", 2 / 7), ("cam1:Gain", 0.03), ("Stats1:CentroidThreshold", 100)):
        assert put_status("DEMO:" + pv, v) == 1

    def camera_y():
        assert put_status("DEMO:cam1:Acquire", 1, timeout=10) == 1
        assert ca.get(connect("DEMO:Stats1:MaxValue_RBV")) < 65535
        return ca.get(connect("DEMO:Stats1:CentroidY_RBV"))
    c0 = camera_y()
    assert abs(ca.get(connect(p + "SumAll:MeanValue_RBV")) - 1.0) < 0.01  # the slit passes it all
    pitch = epics.Motor("DEMO:MirrorPitch", timeout=5)
    pitch.put("CNEN", 1, wait=True)
    assert pitch.move(0.001, wait=True, timeout=20) == 0  # mrad
    y1, _ = reading()
    assert 15 < y1 - y0 < 28, (y0, y1)
    c1 = camera_y()  # the camera sees the same move: rows count downwards
    assert abs((c0 - c1) - (y1 - y0) / 5) < 1.0, (c0, c1, y0, y1)
    assert epics.caput("DEMO:epidFast1.FBON", 1, wait=True) == 1
    assert epics.caput("DEMO:epidFast1.PROC", 1, wait=True) == 1
    y2, closed_rms = reading()
    assert abs(y2) < 1, y2
    assert closed_rms < open_rms / 4, (open_rms, closed_rms)
    assert ca.get(connect("DEMO:epidFast1.OVAL")) < -2  # the piezo took the pitch out (5 um/V)
