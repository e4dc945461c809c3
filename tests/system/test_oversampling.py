"""Oversampling terminals through Channel Access (pyepics): an EL3702 and an EL4732 at 10 samples
per cycle (ecmccfg NELM). The EL3702's memory-map waveform ($(P)m0s001-AI01-Arr) shows 10
samples of a signal per cycle; a waveform put to the EL4732 ($(P)m0s002-AO01-Arr) is sent sample
for sample (the plant wires it to the EL3702's channel 2, read back as -AI02-Arr); a PLC copies
memory maps by ECMC id; a factor outside the terminal's range is refused with file:line:col."""

import subprocess

import numpy as np
from epics import ca

from conftest import BEAMCTL, RunServer, acquire_port, connect, forget_pvs, release_port, require_binary, wait_for

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim, plant: plant.yaml}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL3702, oversampling: {n}}}
      - {{position: 2, type: EL4732, oversampling: 10}}
plcs:
  - {{id: 0, file: copy.plc}}
"""

# channel 1: a 100 Hz ramp of +-5 V (0.1 V = 327.67 digits per 100 us sample); EL4732 ch1 -> EL3702 ch2
PLANT = """
signals:
  - {to: s1.analogInputArray01_1, shape: ramp, amplitude: 5, frequency: 100}
wiring:
  - {from: s2.analogOutput01_1, to: s1.analogInputArray02_1}
"""

# memory maps: 0, 1 = EL3702 ch1, ch2; 2, 3 = EL4732 ch1, ch2. The PLC mirrors EL3702 ch1 into
# EL4732 ch2 and counts the samples.
PLC = """
ec_mm_cp(0, 3);
static.size := ec_get_mm_size(0);
"""


def write_ioc(tmp_path, prefix, n=10):
    (tmp_path / "plant.yaml").write_text(PLANT)
    (tmp_path / "copy.plc").write_text(PLC)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name=prefix.rstrip(":"), prefix=prefix, n=n))
    return cfg


def test_waveforms_of_an_oversampling_terminal(tmp_path, prefix):
    require_binary()
    p = prefix
    cfg = write_ioc(tmp_path, p)
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    try:
        srv.start()
        ai1 = connect(p + "m0s001-AI01-Arr")
        assert ca.element_count(ai1) == 10
        assert ca.field_type(ai1) == ca.dbr.SHORT
        assert wait_for(lambda: ca.get(connect(p + "m0-Stat-OK")) == 1)
        # 10 samples of the ramp per cycle, 100 us apart: consecutive samples 327.67 digits apart
        # (one may fall where the ramp wraps)
        def ramp_ok():
            s = np.asarray(ca.get(ai1), dtype=float)
            steps = np.diff(s)
            return len(s) == 10 and np.sum(np.abs(steps - 327.67) < 2) >= 8
        assert wait_for(ramp_ok, timeout=5), ca.get(ai1)
        # a put to the EL4732's channel 1 arrives on the EL3702's channel 2, sample for sample
        want = [-4000 + 900 * k for k in range(10)]
        ao1 = connect(p + "m0s002-AO01-Arr")
        assert ca.put(ao1, want, wait=True) == 1
        ai2 = connect(p + "m0s001-AI02-Arr")
        assert wait_for(lambda: list(ca.get(ai2)) == want, timeout=5), ca.get(ai2)
        # the PLC's ec_mm_cp(0, 3) sends the EL3702's channel 1 out of the EL4732's channel 2
        assert wait_for(lambda: ca.get(connect(p + "PLC00-Scans")) > 10)
        # an input array is the terminal's: CA clients may not write it (the output array they may)
        assert ca.write_access(ai1) == 0
        assert ca.write_access(ao1) == 1
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(p)
        release_port(port)


def test_a_factor_outside_the_range_is_refused(tmp_path, prefix):
    require_binary()
    cfg = write_ioc(tmp_path, prefix, n=101)
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0
    assert "ioc.yaml:9:51:" in r.stdout + r.stderr, r.stdout + r.stderr
    assert "EL3702: oversampling factor 101 should be 1..100" in r.stdout + r.stderr, r.stdout + r.stderr
