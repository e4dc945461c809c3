"""GR/CTRL metadata (units, precision, display/control/alarm limits with the NaN rule), enum
strings, DBR layouts, timestamps and UDF (ca-protocol.md §5, §6; records.md §0)."""

import math
import time

import pytest

import ca_raw as raw
from conftest import connect, module_server

import epics
from epics import ca, dbr

NAN = float("nan")

DB = """
record(ai, "$(P)ai") {
    field(EGU, "mm") field(PREC, "3") field(HOPR, "100") field(LOPR, "-100")
    field(HIHI, "90") field(HHSV, "MAJOR") field(HIGH, "80") field(HSV, "NO_ALARM")
    field(LOW, "10") field(LSV, "MINOR") field(LOLO, "0")
}
record(ao, "$(P)ao") {
    field(EGU, "V") field(PREC, "2") field(HOPR, "10") field(LOPR, "-10")
    field(DRVH, "5") field(DRVL, "-5") field(HIGH, "4") field(HSV, "MINOR")
}
record(longout, "$(P)lo") {
    field(EGU, "cnt") field(HOPR, "1000") field(LOPR, "-1000") field(DRVH, "500")
    field(DRVL, "-500") field(HIHI, "900") field(HHSV, "MAJOR") field(LOW, "-50")
    field(LSV, "MINOR")
}
record(longin, "$(P)li") { field(HOPR, "50") field(LOPR, "5") field(HIGH, "40") field(HSV, "MINOR") }
record(ai, "$(P)none") { }
record(mbbo, "$(P)mbbo") { field(ZRST, "A") field(TWST, "C") }
record(mbbi, "$(P)mbbi") {
    field(ZRST, "s0") field(ONST, "s1") field(TWST, "s2") field(THST, "s3") field(FRST, "s4")
    field(FVST, "s5") field(SXST, "s6") field(SVST, "s7") field(EIST, "s8") field(NIST, "s9")
    field(TEST, "s10") field(ELST, "s11") field(TVST, "s12") field(TTST, "s13")
    field(FTST, "s14") field(FFST, "twenty_five_characters_xx")
}
record(bo, "$(P)bo") { field(ZNAM, "Off") field(ONAM, "On") }
record(ai, "$(P)udf") { }
record(ai, "$(P)pini") { field(VAL, "5") field(PINI, "YES") }
record(ai, "$(P)valnopini") { field(VAL, "5") }
record(stringin, "$(P)si") { }
record(ai, "$(P)ts") { field(EGU, "s") }
"""


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    yield from module_server(tmp_path_factory, DB, name="meta")


@pytest.fixture
def rawc(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        yield c


def same(a, b):
    """Equality where NaN equals NaN."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def check(d, **expected):
    bad = {k: (d.get(k), v) for k, v in expected.items() if not same(d.get(k), v)}
    assert not bad, f"metadata mismatch (got, want): {bad}"


def test_ai_ctrl_double_nan_rule(srv):
    md = ca.get_ctrlvars(connect(srv.pv("ai")))
    check(md, precision=3, units="mm", upper_disp_limit=100.0, lower_disp_limit=-100.0,
          upper_alarm_limit=90.0, upper_warning_limit=NAN, lower_warning_limit=10.0,
          lower_alarm_limit=NAN, upper_ctrl_limit=100.0, lower_ctrl_limit=-100.0)


def test_ai_metadata_raw_layouts(srv, rawc):
    ch = rawc.create(srv.pv("ai"))
    m, d = rawc.read(ch, dtype=raw.CTRL_DOUBLE)
    assert (m.dtype, m.count, m.postsize) == (raw.CTRL_DOUBLE, 1, 88)
    check(d, precision=3, units="mm", upper_disp=100.0, lower_disp=-100.0, upper_alarm=90.0,
          upper_warning=NAN, lower_warning=10.0, lower_alarm=NAN, upper_ctrl=100.0,
          lower_ctrl=-100.0, status=17, severity=3)
    m, d = rawc.read(ch, dtype=raw.GR_DOUBLE)
    assert m.postsize == 72
    check(d, precision=3, units="mm", upper_disp=100.0, upper_warning=NAN, upper_alarm=90.0)
    m, d = rawc.read(ch, dtype=raw.CTRL_FLOAT)
    assert m.postsize == 56  # 52 padded to 8
    check(d, precision=3, units="mm", upper_disp=100.0, lower_warning=10.0)
    assert math.isnan(d["upper_warning"]) and math.isnan(d["lower_alarm"])
    # integer DBRs carry 0 where the double form has NaN (§6, seen)
    m, d = rawc.read(ch, dtype=raw.CTRL_LONG)
    assert m.postsize == 48
    check(d, units="mm", upper_disp=100, lower_disp=-100, upper_alarm=90, upper_warning=0,
          lower_warning=10, lower_alarm=0, upper_ctrl=100, lower_ctrl=-100)
    m, d = rawc.read(ch, dtype=raw.CTRL_SHORT)
    assert m.postsize == 32
    check(d, units="mm", upper_disp=100, lower_disp=-100, upper_alarm=90, upper_warning=0,
          lower_warning=10, lower_alarm=0, upper_ctrl=100, lower_ctrl=-100)
    m, d = rawc.read(ch, dtype=raw.CTRL_CHAR)
    assert m.postsize == 24
    check(d, units="mm", upper_disp=100, upper_alarm=90, upper_warning=0, lower_warning=10)


def test_ao_ctrl_limits_are_drvh_drvl(srv):
    md = ca.get_ctrlvars(connect(srv.pv("ao")))
    check(md, precision=2, units="V", upper_disp_limit=10.0, lower_disp_limit=-10.0,
          upper_ctrl_limit=5.0, lower_ctrl_limit=-5.0, upper_warning_limit=4.0,
          upper_alarm_limit=NAN, lower_warning_limit=NAN, lower_alarm_limit=NAN)


def test_long_records_ctrl(srv, rawc):
    md = ca.get_ctrlvars(connect(srv.pv("lo")))
    check(md, units="cnt", upper_disp_limit=1000, lower_disp_limit=-1000,
          upper_ctrl_limit=500, lower_ctrl_limit=-500, upper_alarm_limit=900,
          upper_warning_limit=0, lower_warning_limit=-50, lower_alarm_limit=0)
    ch = rawc.create(srv.pv("lo"))
    _m, d = rawc.read(ch, dtype=raw.CTRL_DOUBLE)
    check(d, units="cnt", precision=0, upper_alarm=900.0, upper_warning=NAN, lower_warning=-50.0,
          lower_alarm=NAN, upper_ctrl=500.0, lower_ctrl=-500.0)
    md = ca.get_ctrlvars(connect(srv.pv("li")))
    check(md, upper_disp_limit=50, lower_disp_limit=5, upper_ctrl_limit=50, lower_ctrl_limit=5,
          upper_warning_limit=40, upper_alarm_limit=0, lower_warning_limit=0,
          lower_alarm_limit=0)


def test_no_alarm_limits_all_nan(srv):
    md = ca.get_ctrlvars(connect(srv.pv("none")))
    check(md, upper_alarm_limit=NAN, upper_warning_limit=NAN, lower_warning_limit=NAN,
          lower_alarm_limit=NAN, upper_disp_limit=0.0, lower_disp_limit=0.0, units="",
          precision=0)


def test_field_metadata_like_airecord(srv, rawc):
    """Non-VAL fields: DOUBLE fields of ai carry EGU/PREC and HOPR/LOPR for HIHI etc.; fields
    without display support get their type's full range; alarm limits are NaN (§6)."""
    ch = rawc.create(srv.pv("ai.HIHI"))
    _m, d = rawc.read(ch, dtype=raw.CTRL_DOUBLE)
    check(d, units="mm", precision=3, upper_disp=100.0, lower_disp=-100.0, upper_alarm=NAN,
          upper_warning=NAN, lower_warning=NAN, lower_alarm=NAN)
    assert d["value"] == [90.0]
    ch = rawc.create(srv.pv("ai.PREC"))
    _m, d = rawc.read(ch, dtype=raw.CTRL_SHORT)
    check(d, units="", upper_disp=32767, lower_disp=-32768, upper_ctrl=32767, lower_ctrl=-32768)
    assert d["value"] == [3]


def test_enum_strings(srv, rawc):
    assert ca.get_enum_strings(connect(srv.pv("mbbo"))) == ("A", "", "C")
    assert ca.get_enum_strings(connect(srv.pv("bo"))) == ("Off", "On")
    ch = rawc.create(srv.pv("mbbi"))
    m, d = rawc.read(ch, dtype=raw.CTRL_ENUM)
    assert (m.dtype, m.postsize) == (raw.CTRL_ENUM, 424)
    assert d["no_str"] == 16
    assert d["strs"] == ["s%d" % i for i in range(15)] + ["twenty_five_characters_xx"]
    m2, d2 = rawc.read(ch, dtype=raw.CTRL_ENUM - 7)  # GR_ENUM is identical
    assert m2.payload[:422] == m.payload[:422]


def test_udf_and_initial_alarm(srv):
    def tv(name, ftype=dbr.TIME_DOUBLE):
        md = ca.get_with_metadata(connect(srv.pv(name)), ftype=ftype)
        return md["value"], md["severity"], md["status"]

    # never processed: UDF / INVALID; with a VAL given in the .db, status UDF without alarm (as
    # EPICS softIoc R7.0.8.1 shows it: iocInit sets SEVR to UDFS only while UDF is set)
    assert tv("udf") == (0.0, 3, 17)
    assert tv("valnopini") == (5.0, 0, 17)
    assert tv("si", dbr.TIME_STRING) == ("", 3, 17)
    assert epics.caget(srv.pv("udf.UDF"), use_monitor=False) == 1
    # PINI processes at start: defined, no alarm
    assert tv("pini") == (5.0, 0, 0)
    assert epics.caget(srv.pv("pini.UDF"), use_monitor=False) == 0
    # a put processes the record and clears UDF
    assert ca.put(connect(srv.pv("udf")), 1.5, wait=True) == 1
    assert tv("udf") == (1.5, 0, 0)
    assert epics.caget(srv.pv("udf.UDF"), use_monitor=False) == 0
    assert epics.caget(srv.pv("udf.SEVR"), as_string=True, use_monitor=False) == "NO_ALARM"


def test_timestamps(srv, rawc):
    chid = connect(srv.pv("ts"))
    before = time.time()
    assert ca.put(chid, 1.0, wait=True) == 1
    md1 = ca.get_with_metadata(chid, ftype=dbr.TIME_DOUBLE)
    after = time.time()
    assert before - 1.0 <= md1["timestamp"] <= after + 1.0, "TIME stamp is the process time"
    time.sleep(0.05)
    assert ca.put(chid, 2.0, wait=True) == 1
    md2 = ca.get_with_metadata(chid, ftype=dbr.TIME_DOUBLE)
    assert md2["timestamp"] > md1["timestamp"]
    # on the wire: seconds since 1990 plus nanoseconds, same stamp for every field (§6)
    val = rawc.create(srv.pv("ts"))
    egu = rawc.create(srv.pv("ts.EGU"))
    _m, dv = rawc.read(val, dtype=raw.TIME_DOUBLE)
    _m, de = rawc.read(egu, dtype=raw.TIME_STRING)
    # pyepics passes the stamp on as integers and as a float of whole microseconds
    # (posix secs + 1e-6 * int(nsec / 1000)); compare exactly, in integers (the double resolves
    # 0.24 us at today's epoch, so the microseconds round back without error)
    assert (md2["posixseconds"], md2["nanoseconds"]) == (dv["secs"] + raw.EPICS_EPOCH, dv["nsec"])
    frac_us = round((md2["timestamp"] - md2["posixseconds"]) * 1e6)
    assert frac_us == dv["nsec"] // 1000, (md2, dv)
    assert 0 <= dv["nsec"] < 1_000_000_000
    assert (de["secs"], de["nsec"]) == (dv["secs"], dv["nsec"])
    assert de["value"] == ["s"]
