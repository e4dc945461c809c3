"""caget/caput of every native DBR type, enums by string and index, 1 MB arrays, long strings,
field channels and name resolution (ca-protocol.md §3, §5, §6)."""

import numpy as np
import pytest

import ca_raw as raw
from conftest import connect, module_server, not_connecting

import epics
from epics import ca, dbr

FTVLS = {  # FTVL -> (native DBR type over CA, test values as written, values read back natively)
    "CHAR": (dbr.CHAR, [0, 1, 127, 128, 255], [0, 1, 127, 128, 255]),
    "UCHAR": (dbr.CHAR, [0, 1, 127, 128, 255], [0, 1, 127, 128, 255]),
    "SHORT": (dbr.INT, [-32768, -1, 0, 32767], [-32768, -1, 0, 32767]),
    "USHORT": (dbr.LONG, [0, 1, 65535], [0, 1, 65535]),
    "LONG": (dbr.LONG, [-2147483648, -1, 0, 2147483647], [-2147483648, -1, 0, 2147483647]),
    "ULONG": (dbr.DOUBLE, [0.0, 1.0, 4294967295.0], [0.0, 1.0, 4294967295.0]),
    "FLOAT": (dbr.FLOAT, [1.5, -2.25, 2.0 ** 100, 0.0], [1.5, -2.25, 2.0 ** 100, 0.0]),
    "DOUBLE": (dbr.DOUBLE, [1e300, -1.0 / 3, 5e-324, 0.0], [1e300, -1.0 / 3, 5e-324, 0.0]),
    "STRING": (dbr.STRING, ["a", "hello world", "x" * 39], ["a", "hello world", "x" * 39]),
}

LONG_TAIL = "long_record_name_for_the_NAME_field_test_"  # makes the full name > 40 chars

DB = """
record(ai, "$(P)ai") { field(PREC, "3") field(EGU, "mm") field(HOPR, "10") field(LOPR, "-10") }
record(ai, "$(P)ai2") { field(PREC, "3") }
record(ao, "$(P)ao") { field(PREC, "2") field(DRVH, "100") field(DRVL, "-100") }
record(longin, "$(P)li") { field(VAL, "7") field(PINI, "YES") }
record(longout, "$(P)lo") { field(DRVH, "1000") field(DRVL, "-1000") }
record(bi, "$(P)bi") { field(ZNAM, "Closed") field(ONAM, "Open") }
record(bo, "$(P)bo") { field(ZNAM, "Off") field(ONAM, "On") }
record(bo, "$(P)bo2") { field(ZNAM, "Off") field(ONAM, "On") }
record(mbbi, "$(P)mbbi") { field(ZRST, "Z") field(ONST, "O") field(TWST, "T") }
record(mbbo, "$(P)mbbo") {
    field(ZRST, "Zero") field(ONST, "One") field(TWST, "Two") field(THST, "Three")
}
record(mbbo, "$(P)mbbo2") {
    field(ZRST, "Zero") field(ONST, "One") field(TWST, "Two") field(THST, "Three")
}
record(stringin, "$(P)si") { field(VAL, "initial") field(PINI, "YES") }
record(stringout, "$(P)so") { }
record(waveform, "$(P)big_d") { field(FTVL, "DOUBLE") field(NELM, "131072") }
record(waveform, "$(P)big_c") { field(FTVL, "UCHAR") field(NELM, "1048576") }
record(waveform, "$(P)path") { field(FTVL, "CHAR") field(NELM, "256") }
record(ai, "$(P)%s") { field(DESC, "named") }
""" % LONG_TAIL + "".join(
    'record(waveform, "$(P)wf_%s") { field(FTVL, "%s") field(NELM, "8") }\n'
    'record(waveform, "$(P)s_%s") { field(FTVL, "%s") field(NELM, "1") }\n' % (t, t, t, t)
    for t in FTVLS)


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    yield from module_server(tmp_path_factory, DB, name="types")


@pytest.fixture
def rawc(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        yield c


NATIVE = [  # (record/field suffix, DBR type, element count)
    ("ai", dbr.DOUBLE, 1), ("ao", dbr.DOUBLE, 1), ("li", dbr.LONG, 1), ("lo", dbr.LONG, 1),
    ("bi", dbr.ENUM, 1), ("bo", dbr.ENUM, 1), ("mbbi", dbr.ENUM, 1), ("mbbo", dbr.ENUM, 1),
    ("si", dbr.STRING, 1), ("so", dbr.STRING, 1),
    ("ai.DESC", dbr.STRING, 1), ("ai.EGU", dbr.STRING, 1), ("ai.PREC", dbr.INT, 1),
    ("ai.HOPR", dbr.DOUBLE, 1), ("ai.HHSV", dbr.ENUM, 1), ("ai.SEVR", dbr.ENUM, 1),
    ("ai.STAT", dbr.ENUM, 1), ("ai.SCAN", dbr.ENUM, 1), ("ai.PINI", dbr.ENUM, 1),
    ("ai.UDF", dbr.CHAR, 1), ("ai.PROC", dbr.CHAR, 1), ("ai.NAME", dbr.STRING, 1),
    ("ai.RTYP", dbr.STRING, 1), ("ai.ASG", dbr.STRING, 1), ("ai.MDEL", dbr.DOUBLE, 1),
    ("li.MDEL", dbr.LONG, 1), ("li.HIHI", dbr.LONG, 1), ("lo.DRVH", dbr.LONG, 1),
    ("mbbo.ZRVL", dbr.DOUBLE, 1), ("mbbo.ZRST", dbr.STRING, 1), ("mbbo.UNSV", dbr.ENUM, 1),
    ("bo.ZNAM", dbr.STRING, 1), ("bo.COSV", dbr.ENUM, 1),
    ("wf_DOUBLE.NORD", dbr.DOUBLE, 1), ("wf_DOUBLE.NELM", dbr.DOUBLE, 1),
    ("wf_DOUBLE.FTVL", dbr.ENUM, 1),
    ("ai.DESC$", dbr.CHAR, 41), ("ai.NAME$", dbr.CHAR, 61), ("so.VAL$", dbr.CHAR, 40),
    ("big_d", dbr.DOUBLE, 131072), ("big_c", dbr.CHAR, 1048576),
] + [("wf_" + t, FTVLS[t][0], 8) for t in FTVLS] + [("s_" + t, FTVLS[t][0], 1) for t in FTVLS]


@pytest.mark.parametrize("suffix,ftype,count", NATIVE, ids=[n[0] for n in NATIVE])
def test_native_type_and_count(srv, suffix, ftype, count):
    chid = connect(srv.pv(suffix))
    assert (ca.field_type(chid), ca.element_count(chid)) == (ftype, count), \
        f"{suffix}: native (DBR type, count) (spec §5 'Native type from DBF')"


@pytest.mark.parametrize("ftvl", list(FTVLS))
def test_waveform_roundtrip_every_ftvl(srv, ftvl):
    ftype, written, expected = FTVLS[ftvl]
    pv = epics.PV(srv.pv("wf_" + ftvl), auto_monitor=False)
    assert pv.wait_for_connection(5)
    assert pv.put(written, wait=True, timeout=10) == 1
    got = pv.get(use_monitor=False, timeout=5)
    # count=0 request: the server returns NORD elements, not NELM (minor 13, §1)
    assert len(got) == len(written)
    if ftype == dbr.STRING:
        assert list(got) == expected
    elif ftype in (dbr.FLOAT, dbr.DOUBLE):
        assert [float(x) for x in got] == expected
    else:
        assert [int(x) for x in got] == expected
    assert epics.caget(srv.pv("wf_%s.NORD" % ftvl), use_monitor=False) == len(written)


@pytest.mark.parametrize("ftvl", list(FTVLS))
def test_scalar_waveform_every_ftvl(srv, ftvl):
    ftype, written, expected = FTVLS[ftvl]
    chid = connect(srv.pv("s_" + ftvl))
    assert ca.put(chid, written[-2], wait=True) == 1
    got = ca.get(chid)
    assert got == expected[-2]


def test_char_conversions_signedness(srv):
    """DBR_CHAR is u8 on the wire; CHAR waveforms hold signed bytes, UCHAR unsigned (§5)."""
    for ftvl in ("CHAR", "UCHAR"):
        chid = connect(srv.pv("wf_" + ftvl))
        assert ca.put(chid, [0, 1, 127, 128, 255], wait=True) == 1
    as_long = {ftvl: [int(v) for v in ca.get(connect(srv.pv("wf_" + ftvl)), ftype=dbr.LONG)]
               for ftvl in ("CHAR", "UCHAR")}
    assert as_long["CHAR"] == [0, 1, 127, -128, -1]
    assert as_long["UCHAR"] == [0, 1, 127, 128, 255]


def test_scalar_puts_and_clamping(srv):
    ai = connect(srv.pv("ai"))
    assert ca.put(ai, 1.25, wait=True) == 1
    assert ca.get(ai) == 1.25
    ao = connect(srv.pv("ao"))
    assert ca.put(ao, 150.0, wait=True) == 1
    assert ca.get(ao) == 100.0, "ao clamps VAL to DRVH"
    assert ca.put(ao, -150.5, wait=True) == 1
    assert ca.get(ao) == -100.0, "ao clamps VAL to DRVL"
    assert ca.put(ao, 42.5, wait=True) == 1
    assert ca.get(ao) == 42.5
    lo = connect(srv.pv("lo"))
    assert ca.put(lo, 5000, wait=True) == 1
    assert ca.get(lo) == 1000
    assert ca.put(lo, -5000, wait=True) == 1
    assert ca.get(lo) == -1000
    assert ca.put(lo, -7, wait=True) == 1
    assert ca.get(lo) == -7
    li = connect(srv.pv("li"))
    assert ca.get(li) == 7
    so = connect(srv.pv("so"))
    assert ca.put(so, "hello there", wait=True) == 1
    assert ca.get(so) == "hello there"
    si = connect(srv.pv("si"))
    assert ca.get(si) == "initial"


def test_enum_by_string_and_index(srv):
    pv = epics.PV(srv.pv("mbbo"), auto_monitor=False)
    assert pv.wait_for_connection(5)
    assert pv.put("Two", wait=True) == 1
    assert pv.get(use_monitor=False) == 2
    assert pv.get(as_string=True, use_monitor=False) == "Two"
    assert pv.put(3, wait=True) == 1
    assert pv.get(use_monitor=False) == 3
    assert pv.get(as_string=True, use_monitor=False) == "Three"
    assert pv.enum_strs == ("Zero", "One", "Two", "Three")
    bo = epics.PV(srv.pv("bo"), auto_monitor=False)
    assert bo.wait_for_connection(5)
    assert bo.put("On", wait=True) == 1
    assert bo.get(use_monitor=False) == 1
    assert bo.get(as_string=True, use_monitor=False) == "On"
    assert bo.put(0, wait=True) == 1
    assert bo.get(as_string=True, use_monitor=False) == "Off"
    # the server converts enums to their state string for DBR_STRING reads (§6)
    assert ca.get(connect(srv.pv("mbbo")), ftype=dbr.STRING) == "Three"
    assert ca.get(connect(srv.pv("bo")), ftype=dbr.STRING) == "Off"


def test_server_side_string_conversions(srv, rawc):
    """Writes of DBR_STRING are converted by the server; enums match a state or a number (§6)."""
    ch = rawc.create(srv.pv("mbbo2"))
    assert ch["dtype"] == raw.ENUM
    for text, expect in (("Two", 2), ("1", 1), ("Three", 3), ("0", 0)):
        m = rawc.write_notify(ch, [text], dtype=raw.STRING)
        assert m.p1 == raw.ECA_NORMAL, f"write '{text}' to mbbo: status {m.p1}"
        assert rawc.read(ch)[1]["value"] == [expect]
        assert rawc.read(ch, dtype=raw.STRING)[1]["value"] == [
            ["Zero", "One", "Two", "Three"][expect]]
    # a string that is neither a state nor an index below no_str fails and changes nothing
    for bad in ("Bogus", "4", "two"):
        m = rawc.write_notify(ch, [bad], dtype=raw.STRING)
        assert m.p1 == raw.ECA_PUTFAIL, f"write '{bad}' to mbbo: status {m.p1}, want ECA_PUTFAIL"
        assert rawc.read(ch)[1]["value"] == [0]
    bo = rawc.create(srv.pv("bo2"))
    assert rawc.write_notify(bo, ["On"], dtype=raw.STRING).p1 == raw.ECA_NORMAL
    assert rawc.read(bo)[1]["value"] == [1]
    assert rawc.write_notify(bo, ["Maybe"], dtype=raw.STRING).p1 == raw.ECA_PUTFAIL
    assert rawc.read(bo)[1]["value"] == [1]
    # numeric conversions in both directions
    ai = rawc.create(srv.pv("ai2"))
    assert rawc.write_notify(ai, ["42.5"], dtype=raw.STRING).p1 == raw.ECA_NORMAL
    assert rawc.read(ai)[1]["value"] == [42.5]
    assert rawc.write_notify(ai, [1.23456], dtype=raw.DOUBLE).p1 == raw.ECA_NORMAL
    assert rawc.read(ai, dtype=raw.STRING)[1]["value"] == ["1.235"], "DBR_STRING uses PREC=3"
    assert rawc.read(ai, dtype=raw.LONG)[1]["value"] == [1]
    assert rawc.write_notify(ai, [-7], dtype=raw.SHORT).p1 == raw.ECA_NORMAL
    assert rawc.read(ai)[1]["value"] == [-7.0]
    assert rawc.write_notify(ai, [2], dtype=raw.ENUM).p1 == raw.ECA_NORMAL
    assert rawc.read(ai, dtype=raw.FLOAT)[1]["value"] == [2.0]


def test_one_megabyte_arrays(srv):
    rng = np.random.default_rng(1234)
    data_d = rng.normal(size=131072)
    chid = connect(srv.pv("big_d"))
    assert ca.put(chid, data_d, wait=True, timeout=30) == 1
    got = ca.get(chid, timeout=30)
    assert got is not None and len(got) == 131072
    assert np.array_equal(np.asarray(got), data_d)
    assert list(ca.get(chid, count=10)) == list(data_d[:10])

    data_c = rng.integers(0, 256, size=1048576, dtype=np.uint8)
    chid_c = connect(srv.pv("big_c"))
    assert ca.put(chid_c, data_c, wait=True, timeout=30) == 1
    got_c = ca.get(chid_c, timeout=30)
    assert got_c is not None and len(got_c) == 1048576
    assert np.array_equal(np.asarray(got_c, dtype=np.uint8), data_c)

    # a shorter write sets NORD; a count=0 read returns exactly NORD elements
    assert ca.put(chid, np.arange(1000, dtype=float), wait=True) == 1
    got = ca.get(chid, timeout=30)
    assert len(got) == 1000 and got[999] == 999.0
    assert epics.caget(srv.pv("big_d.NORD"), use_monitor=False) == 1000


def test_long_strings(srv):
    # CHAR waveform used as a long string (ADCore FilePath style)
    text = "/data/" + "p" * 200 + "/file.h5"
    pv = epics.PV(srv.pv("path"), auto_monitor=False)
    assert pv.wait_for_connection(5)
    assert pv.put(text, wait=True) == 1
    assert pv.get(as_string=True, use_monitor=False) == text

    # FIELD$ on a STRING field is a CHAR array of the field size (§6)
    desc = "D" * 40  # DESC holds 40 characters + NUL
    d = epics.PV(srv.pv("so.DESC$"), auto_monitor=False)
    assert d.wait_for_connection(5)
    assert d.put(desc, wait=True) == 1
    assert d.get(as_string=True, use_monitor=False) == desc
    # the plain DBR_STRING field is limited to 40 bytes including the NUL
    assert epics.caget(srv.pv("so.DESC"), use_monitor=False) == desc[:39]

    full = srv.prefix + LONG_TAIL
    assert len(full) > 40
    assert epics.caget(srv.pv(LONG_TAIL + ".NAME"), use_monitor=False) == full[:39]
    n = epics.PV(srv.pv(LONG_TAIL + ".NAME$"), auto_monitor=False)
    assert n.wait_for_connection(5)
    assert n.get(as_string=True, use_monitor=False) == full

    # VAL$ of a stringout round-trips 39 characters
    s39 = "abcdefghijklmnopqrstuvwxyz0123456789ABC"
    assert epics.caput(srv.pv("so"), s39, wait=True) == 1
    v = epics.PV(srv.pv("so.VAL$"), auto_monitor=False)
    assert v.wait_for_connection(5)
    assert v.get(as_string=True, use_monitor=False) == s39


def test_field_channels(srv):
    assert epics.caget(srv.pv("ai.EGU"), use_monitor=False) == "mm"
    assert epics.caget(srv.pv("ai.PREC"), use_monitor=False) == 3
    assert epics.caget(srv.pv("ai.RTYP"), use_monitor=False) == "ai"
    assert epics.caget(srv.pv("mbbo.RTYP"), use_monitor=False) == "mbbo"
    assert epics.caget(srv.pv("ai.HOPR"), use_monitor=False) == 10.0
    assert epics.caget(srv.pv("ai.NAME"), use_monitor=False) == srv.pv("ai")
    assert epics.caget(srv.pv("ai.DESC"), use_monitor=False) == ""
    assert epics.caget(srv.pv(LONG_TAIL + ".DESC"), use_monitor=False) == "named"
    scan = epics.PV(srv.pv("ai.SCAN"), auto_monitor=False)
    assert scan.wait_for_connection(5)
    scan.get_ctrlvars()
    assert scan.enum_strs == ("Passive", "Event", "I/O Intr", "10 second", "5 second",
                              "2 second", "1 second", ".5 second", ".2 second", ".1 second")
    assert scan.get(as_string=True, use_monitor=False) == "Passive"
    hhsv = epics.PV(srv.pv("ai.HHSV"), auto_monitor=False)
    assert hhsv.wait_for_connection(5)
    hhsv.get_ctrlvars()
    assert hhsv.enum_strs == ("NO_ALARM", "MINOR", "MAJOR", "INVALID")
    assert hhsv.get(as_string=True, use_monitor=False) == "NO_ALARM"
    # writing metadata fields through their own channels
    assert epics.caput(srv.pv("ai2.EGU"), "V", wait=True) == 1
    assert epics.caget(srv.pv("ai2.EGU"), use_monitor=False) == "V"
    assert epics.caput(srv.pv("ai2.HHSV"), "MAJOR", wait=True) == 1
    assert epics.caget(srv.pv("ai2.HHSV"), use_monitor=False) == 2


def test_unknown_and_foreign_fields_do_not_connect(srv, rawc):
    for name in ("ai.NOPE", "ai.ZNAM", "bo.PREC", "mbbo.DRVH", "nosuchrecord", "ai.val"):
        assert rawc.create(srv.pv(name)) is None, f"{name}: CREATE_CHAN should fail (contract)"
    # and pyepics never sees them connect
    assert not_connecting(srv.pv("ai.NOPE"), timeout=2.0)
    # the circuit still works after the failures
    ok = rawc.create(srv.pv("ai.EGU"))
    assert ok is not None and ok["dtype"] == raw.STRING


def test_access_rights_of_nomod_fields(srv, rawc):
    """SPC_NOMOD fields (NAME, RTYP) are never writable: ACCESS_RIGHTS read only (§3)."""
    assert rawc.create(srv.pv("ai"))["access"] == 3
    assert rawc.create(srv.pv("ai.EGU"))["access"] == 3
    assert rawc.create(srv.pv("ai.NAME"))["access"] == 1
    assert rawc.create(srv.pv("ai.RTYP"))["access"] == 1
