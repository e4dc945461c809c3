"""Two EtherCAT buses in one IOC bridged by a simulated EL6692 (examples/el6692/ioc.yaml), through
Channel Access (pyepics): the undulator's PLC sends the gap on bus 0, the monochromator's PLC reads
it on bus 1 (which runs its own cycle) and answers with an energy; the entries' PVs show both
REAL64 values as numbers.

Rates are measured on the IOC's clock (the timestamps of the values it published), and waits are
for the behaviour, with deadlines that only end a hung test: a loaded machine makes these tests
slower, not red."""

import contextlib
from pathlib import Path

import epics
from epics import ca

from conftest import RunServer, acquire_port, connect, forget_pvs, release_port, require_binary, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


DEADLINE = 30  # [s]


def get(name):
    return ca.get(connect(name))


def value_and_time(name):
    """(value, IOC timestamp [s]) of one fresh read."""
    chid = connect(name)
    md = ca.get_with_metadata(chid, ftype=ca.promote_type(chid, use_time=True), timeout=DEADLINE)
    return md["value"], md["timestamp"]


def published_after(name, t):
    """(value, timestamp) of `name` once the IOC has published it at or after IOC time t."""
    assert wait_for(lambda: value_and_time(name)[1] >= t, timeout=60), \
        f"{name} not published again: {value_and_time(name)}, waiting for a time stamp >= {t}"
    return value_and_time(name)


def example_config(tmp_path, prefix, follow=True):
    text = (EXAMPLES / "el6692" / "ioc.yaml").read_text()
    if not follow:
        assert "    dc_follow: 1" in text
        text = text.replace("    dc_follow: 1", "")
    text = text.replace("ioc: {name: BRIDGE}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    text = text.replace("file: ../", f"file: {EXAMPLES}/")
    for f in ("undulator_plant.yaml", "mono_plant.yaml", "undulator.plc", "mono.plc"):
        text = text.replace(f" {f}", f" {EXAMPLES / 'el6692' / f}")
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(text)
    return cfg


@contextlib.contextmanager
def running_example(tmp_path, prefix, follow=True):
    """The example IOC on a free port, both buses up; stopped and its PVs forgotten after."""
    require_binary()
    port = acquire_port()
    srv = RunServer(tmp_path, example_config(tmp_path, prefix, follow), port).start()
    try:
        assert wait_for(lambda: get(prefix + "m0-Stat-OK") == 1 and get(prefix + "m1-Stat-OK") == 1, 60)
        yield srv
        assert srv.alive()
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


def test_a_value_crosses_the_bridge_both_ways(tmp_path, prefix):
    with running_example(tmp_path, prefix):
        p = prefix
        assert wait_for(lambda: get(p + "m1s001-externalDeviceNotConnected01") == 0, DEADLINE)
        assert get(p + "m0s002-externalDeviceNotConnected01") == 0
        motor = epics.Motor(p + "Gap")
        motor.put("CNEN", 1, wait=True)
        assert wait_for(lambda: get(p + "Gap.CNEN") == 1, DEADLINE)
        assert motor.move(2.5, wait=True, timeout=60) == 0
        rbv = get(p + "Gap.RBV")
        assert abs(rbv - 2.5) < 0.01
        # bus 1 has the gap (a REAL64 entry, read as a number), bus 0 the energy made of it
        assert wait_for(lambda: abs(get(p + "m1s001-inLreal01") - rbv) < 1e-3, DEADLINE)
        assert wait_for(lambda: abs(get(p + "m0s002-inLreal01") - (1000 + 100 * rbv)) < 0.1, DEADLINE)
        assert get(p + "m1s001-inLreal01") != round(get(p + "m1s001-inLreal01"))  # not an integer
        # each master its own cycle: the monochromator's PLC scans in bus 1's (500 Hz)
        assert abs(get(p + "PLC00-ScanTime") - 0.001) < 1e-6
        assert abs(get(p + "PLC01-ScanTime") - 0.002) < 1e-6
        # distributed clocks: bus 1's clock runs 40 ppm fast (mono_plant.yaml's clock: 40 us a
        # second apart) and follows bus 0's (dc_follow): both sides measure the skew, which the
        # steering keeps within a few us, with no drift left: still so in what the IOC publishes
        # a second (of its time) after it first was
        def aligned():
            return all(abs(get(p + n)) < 5e3 for n in ("m0s002-DcSkew", "m1s001-DcSkew")) and abs(get(p + "m0s002-DcDrift")) < 2
        assert wait_for(aligned, 60), (get(p + "m0s002-DcSkew"), get(p + "m0s002-DcDrift"))
        _, t_aligned = value_and_time(p + "m0s002-DcSkew")
        for n in ("m0s002-DcSkew", "m1s001-DcSkew", "m0s002-DcDrift"):
            published_after(p + n, t_aligned + 1.0)
        assert aligned(), (get(p + "m0s002-DcSkew"), get(p + "m0s002-DcDrift"))


def test_without_dc_follow_the_drift_is_measured(tmp_path, prefix):
    """The same buses with bus 1's clock left free: the skew grows by 40 us a second, both sides
    measure it (the other way round), -DcDrift reads 40 and -40 ppm."""
    with running_example(tmp_path, prefix, follow=False):
        p = prefix
        assert wait_for(lambda: abs(get(p + "m0s002-DcDrift") - 40) < 2, 60), get(p + "m0s002-DcDrift")
        assert abs(get(p + "m1s001-DcDrift") + 40) < 2
        skew, t0 = value_and_time(p + "m0s002-DcSkew")
        assert abs(get(p + "m1s001-DcSkew") + skew) < 20e3
        # the skew grows by 40 us a second: over at least 2 s of the IOC's time stamps
        skew1, t1 = published_after(p + "m0s002-DcSkew", t0 + 2.0)
        grown = (skew1 - skew) / (t1 - t0)  # [ns/s]
        assert 20e3 < grown < 60e3, (skew, t0, skew1, t1, grown)
