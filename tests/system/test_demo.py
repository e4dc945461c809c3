"""The demo beamline (examples/demo/ioc.yaml, what `bash build.sh demo` runs): it loads, reaches
OP with all 25 terminals, and its real axes work through their motor records: a slit blade homes and
moves, the absolute-encoder sample axis is referenced at start, the soft records are served."""


import epics
from epics import ca

from conftest import connect, wait_for

AXES = ["SlitTop", "SlitBottom", "SlitLeft", "SlitRight", "SampleX", "SampleY"]




def test_demo_runs_twenty_five_terminals_and_its_axes(demo):
    assert ca.get(connect("DEMO:m0-SlvCntr")) == 25
    for pos in range(25):
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
