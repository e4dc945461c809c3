"""Two EtherCAT buses in one IOC bridged by a simulated EL6692 (examples/el6692/ioc.yaml), through
Channel Access (pyepics): the undulator's PLC sends the gap on bus 0, the monochromator's PLC reads
it on bus 1 (which runs its own cycle) and answers with an energy; the entries' PVs show both
REAL64 values as numbers."""

import time
from pathlib import Path

import epics
from epics import ca

from conftest import RunServer, acquire_port, connect, forget_pvs, release_port, require_binary, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def get(name):
    return ca.get(connect(name))


def test_a_value_crosses_the_bridge_both_ways(tmp_path, prefix):
    require_binary()
    text = (EXAMPLES / "el6692" / "ioc.yaml").read_text()
    text = text.replace("ioc: {name: BRIDGE}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    text = text.replace("file: ../", f"file: {EXAMPLES}/")
    for f in ("undulator_plant.yaml", "mono_plant.yaml", "undulator.plc", "mono.plc"):
        text = text.replace(f" {f}", f" {EXAMPLES / 'el6692' / f}")
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(text)
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port).start()
    try:
        p = prefix
        assert wait_for(lambda: get(p + "m0-Stat-OK") == 1 and get(p + "m1-Stat-OK") == 1, 10)
        assert wait_for(lambda: get(p + "m1s001-externalDeviceNotConnected01") == 0, 5)
        assert get(p + "m0s002-externalDeviceNotConnected01") == 0
        motor = epics.Motor(p + "Gap")
        motor.put("CNEN", 1, wait=True)
        assert wait_for(lambda: get(p + "Gap.CNEN") == 1, 5)
        assert motor.move(2.5, wait=True, timeout=30) == 0
        rbv = get(p + "Gap.RBV")
        assert abs(rbv - 2.5) < 0.01
        # bus 1 has the gap (a REAL64 entry, read as a number), bus 0 the energy made of it
        assert wait_for(lambda: abs(get(p + "m1s001-inLreal01") - rbv) < 1e-3, 5)
        assert wait_for(lambda: abs(get(p + "m0s002-inLreal01") - (1000 + 100 * rbv)) < 0.1, 5)
        assert get(p + "m1s001-inLreal01") != round(get(p + "m1s001-inLreal01"))  # not an integer
        # each master its own cycle: the monochromator's PLC scans in bus 1's (500 Hz)
        assert abs(get(p + "PLC00-ScanTime") - 0.001) < 1e-6
        assert abs(get(p + "PLC01-ScanTime") - 0.002) < 1e-6
        # distributed clocks: bus 1's time base runs 40 ppm fast (mono_plant.yaml's clock); both
        # sides measure the skew, the other way round
        assert wait_for(lambda: abs(get(p + "m0s002-DcDrift") - 40) < 2, 10), get(p + "m0s002-DcDrift")
        assert abs(get(p + "m1s001-DcDrift") + 40) < 2
        skew = get(p + "m0s002-DcSkew")
        assert abs(skew) < 50e6, skew  # what the two masters' DC set-up left, then 40 us more a second
        assert abs(get(p + "m1s001-DcSkew") + skew) < 20e3
        t = time.monotonic()
        time.sleep(1.0)
        later = get(p + "m0s002-DcSkew")
        grown = (later - skew) / (time.monotonic() - t)  # [ns/s]
        assert 20e3 < grown < 60e3, grown
        assert srv.alive()
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)
