"""`beamctl run ioc.yaml`: a simulated EtherCAT segment brought to OP, its master/slave/entry PVs
with ecmccfg names, a DO->DI wiring loop seen through PVs, read-only inputs, and the config CLI."""

import subprocess
import time

import pytest
from epics import ca

from conftest import BEAMCTL, IocServer, RunServer, acquire_port, connect, forget_pvs, release_port, require_binary, wait_for

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 500}}
buses:
  - id: 0
    link: {{type: sim, plant: plant.yaml}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL2008}}
      - {{position: 2, type: EL1008}}
      - {{position: 3, type: EL3104}}
      - {{position: 4, type: EL4134}}
"""

PLANT = """
wiring:
  - {from: s1.binaryOutput03, to: s2.binaryInput05}
  - {from: s1.binaryOutput04, to: s2.binaryInput06}
"""


@pytest.fixture
def bus_ioc(tmp_path, prefix):
    (tmp_path / "plant.yaml").write_text(PLANT)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name=prefix.rstrip(":"), prefix=prefix))
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port).start()
    try:
        yield srv, prefix
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


def get(name, **kw):
    ch = connect(name)
    return ca.get(ch, **kw)


def test_bus_status_pvs(bus_ioc):
    srv, p = bus_ioc
    assert "1 bus(es)" in srv.ready_line
    assert wait_for(lambda: get(p + "m0-Stat-OK") == 1)
    assert get(p + "m0-LinkUp") == 1
    assert get(p + "m0-SlvCntr") == 5
    wc, exp = get(p + "m0-Dom-WC"), get(p + "m0-Dom-WC-Exp")
    # EL2008 and EL4134 write (2 each) and read their status byte (1 each), EL1008 and EL3104 read
    # inputs and status (1 each), the EK1100 its status byte (1)
    assert (wc, exp) == (9, 9)
    assert get(p + "m0-Dom-WC-Complete") == 1
    assert get(p + "m0-MissedFrames") == 0
    assert get(p + "m0-ThdExeMax") > 0
    for pos, typ in [(0, "EK1100"), (1, "EL2008"), (2, "EL1008"), (3, "EL3104"), (4, "EL4134")]:
        assert get(p + f"m0s{pos:03d}-HWType") == typ
        assert wait_for(lambda: get(p + f"m0s{pos:03d}-Online") == 1)
        assert get(p + f"m0s{pos:03d}-Operational") == 1


def test_digital_output_wired_to_input_through_pvs(bus_ioc):
    _srv, p = bus_ioc
    bo3, bi5, bi6 = connect(p + "m0s001-BO03"), connect(p + "m0s002-BI05"), connect(p + "m0s002-BI06")
    assert ca.get(bi5) == 0
    assert ca.put(bo3, 1, wait=True) == 1
    assert wait_for(lambda: ca.get(bi5) == 1, timeout=5)
    assert ca.get(bi6) == 0
    assert ca.get(bi5, as_string=True) == "1"
    assert ca.put(bo3, 0, wait=True) == 1
    assert wait_for(lambda: ca.get(bi5) == 0, timeout=5)


def test_inputs_are_read_only_outputs_writable(bus_ioc):
    _srv, p = bus_ioc
    bi = connect(p + "m0s002-BI01")
    assert ca.read_access(bi) and not ca.write_access(bi)
    bo = connect(p + "m0s001-BO01")
    assert ca.write_access(bo)
    ao = connect(p + "m0s004-AO01")
    assert ca.write_access(ao)
    assert ca.put(ao, 1234, wait=True) == 1
    assert ca.get(ao) == 1234
    ai = connect(p + "m0s003-AI01")
    assert not ca.write_access(ai)
    assert ca.get(ai) == 0


def test_db_and_check_commands(tmp_path):
    require_binary()
    (tmp_path / "plant.yaml").write_text(PLANT)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name="T", prefix="T:"))
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([str(BEAMCTL), "db", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    for name in ["T:m0-Stat-OK", "T:m0s001-BO08", "T:m0s002-BI01", "T:m0s003-AI04", "T:m0s004-AO04"]:
        assert f'"{name}"' in r.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text("ioc: {name: T}\nbuses:\n  - id: 0\n    slaves:\n      - {position: 0, typo: EK1100}\n")
    r = subprocess.run([str(BEAMCTL), "check", str(bad)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1
    assert f"{bad}:5:" in r.stderr and "typo" in r.stderr, r.stderr
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(IOC.format(name="T", prefix="T:").replace("EL3104", "EL9999"))
    r = subprocess.run([str(BEAMCTL), "check", str(wrong)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1 and "EL9999" in r.stderr, r.stderr


def test_startup_sdo_needs_a_coe_device(tmp_path):
    require_binary()
    (tmp_path / "plant.yaml").write_text(PLANT)
    cfg = tmp_path / "ioc.yaml"
    text = IOC.format(name="T", prefix="T:").replace(
        "{position: 2, type: EL1008}", "{position: 2, type: EL1008, sdo: [{index: 0x8000, sub: 1, value: 1, size: 1}]}")
    cfg.write_text(text)
    r = subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True, timeout=30)
    assert r.returncode == 1
    assert "position 2" in r.stderr and "CoE" in r.stderr, r.stderr
