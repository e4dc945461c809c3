"""Feedback through Channel Access (pyepics): synApps' epid record with soft device support holding
a record-made plant through database links, and the fast loop in the cycle behind its epid record
(DTYP "Fast Epid"), examples/feedback/ioc.yaml."""

import time
from pathlib import Path

import epics
from epics import ca

from conftest import connect, put_status, running_config, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def get(name, **kw):
    return ca.get(connect(name), **kw)


def text(name):
    return epics.PV(name).get(as_string=True, use_monitor=False, timeout=5)


def put(name, value):
    assert put_status(name, value) == 1, name


def running_example(tmp_path, prefix):
    cfg = (EXAMPLES / "feedback" / "ioc.yaml").read_text()
    cfg = cfg.replace("ioc: {name: FB}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    cfg = cfg.replace("plant: plant.yaml", f"plant: {EXAMPLES / 'feedback' / 'plant.yaml'}")
    cfg = cfg.replace('{file: soft.db, macros: {P: "FB:"}}', f'{{file: {EXAMPLES / "feedback" / "soft.db"}, macros: {{P: "{prefix}"}}}}')
    return running_config(tmp_path, prefix, cfg, lambda: get(prefix + "m0-Stat-OK") == 1)


def test_the_soft_epid_holds_its_setpoint_through_links(tmp_path, prefix):
    p = prefix
    with running_example(tmp_path, p):
        assert get(p + "epid1.RTYP") == "epid"
        assert text(p + "epid1.FBON") == "Off"
        put(p + "epid1", 4.5)
        put(p + "epid1.FBON", 1)
        # y = 2u + 0.5: u = 2 holds y at 4.5
        assert wait_for(lambda: abs(get(p + "plant:y") - 4.5) < 1e-3, 20)
        assert abs(get(p + "plant:u") - 2.0) < 1e-3
        assert abs(get(p + "epid1.CVAL") - 4.5) < 2e-3
        # a disturbance is taken out again by the integral
        put(p + "plant:disturbance", 1.0)
        assert wait_for(lambda: abs(get(p + "plant:u") - 1.5) < 1e-3, 20)
        assert wait_for(lambda: abs(get(p + "plant:y") - 4.5) < 1e-3, 5)
        assert get(p + "epid1.SEVR") == 0
        # OVAL's control limits are DRVH/DRVL (what a display's slider uses)
        ctrl = ca.get_ctrlvars(connect(p + "epid1.OVAL"))
        assert ctrl["upper_ctrl_limit"] == 10 and ctrl["lower_ctrl_limit"] == -10


def test_the_fast_loop_is_driven_through_its_epid_record(tmp_path, prefix):
    p = prefix
    with running_example(tmp_path, p):
        assert text(p + "epidFast1.DTYP") == "Fast Epid"
        assert text(p + "epidFast1.INP").startswith("@epidFast1")
        put(p + "epidFast1.FBON", 1)
        put(p + "epidFast1", 2.5)
        # the record reads the loop's state back at its scan (.1 s): CVAL is the analog input [V]
        assert wait_for(lambda: abs(get(p + "epidFast1.CVAL") - 2.5) < 4e-4, 20)  # within a digit
        assert abs(get(p + "m0s002-AO01") - round(2.5 / 0.000305185)) <= 2  # the output entry's raw digits
        # the loop is the output's one writer: clients get no write access to its PV
        assert not ca.write_access(connect(p + "m0s002-AO01"))
        assert get(p + "epidFast1.DT") == 0.001  # every cycle
        put(p + "epidFast1.DT", 0.01)
        assert wait_for(lambda: get(p + "epidFast1.DT") == 0.01, 5)
        put(p + "epidFast1", -1.0)
        assert wait_for(lambda: abs(get(p + "epidFast1.CVAL") + 1.0) < 2e-3, 20)
        assert get(p + "epidFast1.SEVR") == 0
        # feedback off: the output stays where the loop left it
        put(p + "epidFast1.FBON", 0)
        put(p + "epidFast1", 3.0)
        assert wait_for(lambda: abs(get(p + "epidFast1.ERR") - (3.0 - get(p + "epidFast1.CVAL"))) < 1e-3, 5)
        raw = get(p + "m0s002-AO01")
        time.sleep(0.5)
        assert get(p + "m0s002-AO01") == raw
        assert abs(get(p + "epidFast1.CVAL") + 1.0) < 2e-3
