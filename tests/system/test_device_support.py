"""Device support "beamctl" seen by a real EPICS client (pyepics): records of an IOC's db: files
read and write EtherCAT process data through "@ec0.s<slave>.<entry>[.<bit>]" links, SCAN
"I/O Intr" records are processed when their signal changes, and an output has one writer."""

import subprocess

import epics
from epics import ca

from conftest import BEAMCTL, connect, running_ioc, wait_for

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim, plant: plant.yaml}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
      - {{position: 2, type: EL2008}}
db:
  - {{file: dev.db, macros: {{P: "{prefix}"}}}}
"""

DB = """
record(bo, "$(P)Valve") {
    field(DTYP, "beamctl")
    field(OUT, "@ec0.s2.binaryOutput03")
    field(ZNAM, "Closed")
    field(ONAM, "Open")
}
record(bi, "$(P)ValveOpen") {
    field(DTYP, "beamctl")
    field(INP, "@ec0.s1.binaryInput03")
    field(SCAN, "I/O Intr")
    field(ZNAM, "no")
    field(ONAM, "yes")
    field(FLNK, "$(P)Opened")
}
record(calc, "$(P)Opened") {
    field(INPA, "$(P)ValveOpen")
    field(CALC, "VAL+A")
}
"""

PLANT = "wiring:\n  - {from: s2.binaryOutput03, to: s1.binaryInput03}\n"


def test_records_read_and_write_bus_signals_and_scan_on_change(tmp_path, prefix):
    files = {"dev.db": DB, "plant.yaml": PLANT}
    with running_ioc(tmp_path, prefix, IOC, files):
        valve, opened = connect(prefix + "Valve"), connect(prefix + "ValveOpen")
        assert ca.get(opened) == 0
        ca.put(valve, 1, wait=True)
        # the output reaches the bus, the wire brings it back, and the I/O Intr record follows
        assert wait_for(lambda: ca.get(opened) == 1, timeout=5)
        assert epics.caget(prefix + "ValveOpen", as_string=True) == "yes"
        assert wait_for(lambda: ca.get(connect(prefix + "Opened")) == 1, timeout=5)
        assert ca.get(connect(prefix + "m0s001-BI03")) == 1
        # one writer: the entry's own PV is now read-only and names the record
        bo = epics.PV(prefix + "m0s002-BO03")
        assert bo.wait_for_connection(5) and not bo.write_access
        assert epics.caget(prefix + "m0s002-BO03.DESC") == f"set by record {prefix}Valve"
        ca.put(valve, 0, wait=True)
        assert wait_for(lambda: ca.get(opened) == 0, timeout=5)
        assert wait_for(lambda: ca.get(connect(prefix + "Opened")) == 1, timeout=5)  # 1 + 0


def test_bad_device_links_are_configuration_errors(tmp_path, prefix):
    bad = DB.replace("@ec0.s1.binaryInput03", "@ec0.s1.noSuchEntry").replace(
        'field(OUT, "@ec0.s2.binaryOutput03")', 'field(OUT, "@ec0.s1.binaryInput01")')
    (tmp_path / "dev.db").write_text(bad)
    (tmp_path / "plant.yaml").write_text(PLANT)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name="X", prefix="X:"))
    r = subprocess.run([str(BEAMCTL), "run", "--ca-port", "1", str(cfg)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode != 0
    assert "no signal 'ec0.s1.noSuchEntry'" in r.stderr, r.stderr
    assert "is an input; an output link cannot write it" in r.stderr, r.stderr
    assert "dev.db:" in r.stderr  # each at its place in the file
