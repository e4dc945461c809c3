"""Monitors: first update, MDEL/ADEL deadbands (recGblCheckDeadband), alarm events, HYST,
DBE_PROPERTY, enums, dynamic-size arrays, cancel (ca-protocol.md §3, §6)."""

import socket
import time

import numpy as np
import pytest

import ca_raw as raw
from conftest import connect, module_server, subscribe, wait_for

import epics
from epics import ca, dbr

VALUE, LOG, ALARM, PROPERTY = dbr.DBE_VALUE, dbr.DBE_LOG, dbr.DBE_ALARM, 8

DB = """
record(ai, "$(P)m0") { }
record(ai, "$(P)m2") { field(MDEL, "2") }
record(ai, "$(P)mneg") { field(MDEL, "-1") }
record(ai, "$(P)adel") { field(ADEL, "5") }
record(longin, "$(P)lm") { field(MDEL, "3") }
record(ai, "$(P)alarm") {
    field(HIHI, "20") field(HHSV, "MAJOR") field(HIGH, "10") field(HSV, "MINOR")
    field(LOW, "-10") field(LSV, "MINOR") field(LOLO, "-20") field(LLSV, "MAJOR")
}
record(ai, "$(P)sevr") { field(HIGH, "10") field(HSV, "MINOR") }
record(ai, "$(P)hyst") { field(HIGH, "10") field(HSV, "MINOR") field(HYST, "2") }
record(longout, "$(P)lohyst") { field(HIGH, "10") field(HSV, "MAJOR") field(HYST, "3") }
record(ai, "$(P)prop") { field(EGU, "mm") field(PREC, "1") field(HOPR, "10") }
record(mbbo, "$(P)enum") { field(ZRST, "Zero") field(ONST, "One") field(TWST, "Two") }
record(bi, "$(P)bi") { field(ZNAM, "Low") field(ONAM, "High") field(OSV, "MAJOR") }
record(waveform, "$(P)wf") { field(FTVL, "DOUBLE") field(NELM, "100") }
record(waveform, "$(P)bigwf") { field(FTVL, "UCHAR") field(NELM, "1048576") }
record(ai, "$(P)cancel") { }
"""


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    yield from module_server(tmp_path_factory, DB, name="monitors")


def put(chid, value):
    assert ca.put(chid, value, wait=True, timeout=10) == 1


def settle(col, n, quiet=0.3):
    """Wait for n events, then make sure no more arrive for `quiet` seconds."""
    assert col.wait_count(n, timeout=10), f"expected {n} monitor updates, got {col.values()}"
    wait_for(lambda: False, timeout=quiet)
    return col.values()


def test_first_update_is_immediate_and_mdel_zero(srv):
    chid = connect(srv.pv("m0"))
    col, _h = subscribe(chid, mask=VALUE)
    assert col.wait_count(1, timeout=5), "EVENT_ADD must send the current value at once"
    for v in (1.0, 1.0, 1.0, 2.0, 2.0, 3.0):
        put(chid, v)
    assert settle(col, 4) == [0.0, 1.0, 2.0, 3.0], "MDEL=0 posts only on change"


def test_mdel_deadband(srv):
    chid = connect(srv.pv("m2"))
    col, _h = subscribe(chid, mask=VALUE)
    assert col.wait_count(1, timeout=5)
    for v in (1.0, 2.5, 4.0, 4.6, 4.6, 6.6, 100.0):
        put(chid, v)
    # post when |v - last posted| > MDEL: 2.5 (2.5>2), 4.6 (2.1>2), not 6.6 (2.0 is not > 2)
    assert settle(col, 4) == [0.0, 2.5, 4.6, 100.0]


def test_mdel_minus_one_posts_every_process(srv):
    chid = connect(srv.pv("mneg"))
    col, _h = subscribe(chid, mask=VALUE)
    assert col.wait_count(1, timeout=5)
    for v in (5.0, 5.0, 5.0, 6.0):
        put(chid, v)
    assert settle(col, 5) == [0.0, 5.0, 5.0, 5.0, 6.0]


def test_adel_archive_deadband(srv):
    chid = connect(srv.pv("adel"))
    log, _h1 = subscribe(chid, mask=LOG)
    val, _h2 = subscribe(chid, mask=VALUE)
    assert log.wait_count(1, timeout=5) and val.wait_count(1, timeout=5)
    for v in (3.0, 6.0, 10.0, 11.5, 100.0):
        put(chid, v)
    assert settle(log, 4) == [0.0, 6.0, 11.5, 100.0], "DBE_LOG posts when |delta| > ADEL"
    assert settle(val, 6, quiet=0.0) == [0.0, 3.0, 6.0, 10.0, 11.5, 100.0]


def test_integer_deadband(srv):
    chid = connect(srv.pv("lm"))
    col, _h = subscribe(chid, mask=VALUE)
    assert col.wait_count(1, timeout=5)
    for v in (1, 2, 3, 4, 6, 100):
        put(chid, v)
    assert settle(col, 3) == [0, 4, 100], "longin MDEL=3: post when |delta| > 3"


def test_alarm_events(srv):
    chid = connect(srv.pv("alarm"))
    col, _h = subscribe(chid, mask=ALARM, use_time=True)
    assert col.wait_count(1, timeout=5)
    for v in (1, 2, 15, 16, -15, 25, 26, 5, -25, 0):
        put(chid, float(v))
    settle(col, 8)
    got = [(e["value"], e["severity"], e["status"]) for e in col.events]
    # severities: 0 NO_ALARM 1 MINOR 2 MAJOR 3 INVALID; status 3 HIHI 4 HIGH 5 LOLO 6 LOW 17 UDF
    assert got == [(0.0, 3, 17), (1.0, 0, 0), (15.0, 1, 4), (-15.0, 1, 6), (25.0, 2, 3),
                   (5.0, 0, 0), (-25.0, 2, 5), (0.0, 0, 0)]


def test_value_and_alarm_mask_combined(srv):
    chid = connect(srv.pv("bi"))
    col, _h = subscribe(chid, mask=VALUE | ALARM, use_time=True)
    assert col.wait_count(1, timeout=5)
    for v in (0, 1, 1, 0):
        put(chid, v)
    settle(col, 4)
    got = [(e["value"], e["severity"]) for e in col.events]
    assert got == [(0, 3), (0, 0), (1, 2), (0, 0)], "bi OSV=MAJOR; first put clears UDF"


def test_sevr_field_monitor(srv):
    chid = connect(srv.pv("sevr"))
    sev = connect(srv.pv("sevr.SEVR"))
    col, _h = subscribe(sev, mask=VALUE)
    assert col.wait_count(1, timeout=5)
    for v in (1.0, 15.0, 16.0, 3.0):
        put(chid, v)
    assert settle(col, 4) == [3, 0, 1, 0], "SEVR field posts on each severity change"


def test_hysteresis(srv):
    chid = connect(srv.pv("hyst"))

    def sevr_after(v):
        put(chid, v)
        return ca.get_with_metadata(chid, ftype=dbr.TIME_DOUBLE)["severity"]

    # HIGH=10 HSV=MINOR HYST=2: once in alarm it stays until VAL < HIGH - HYST
    assert [sevr_after(v) for v in (11.0, 9.0, 8.5, 7.9, 9.0, 10.0)] == [1, 1, 1, 0, 0, 1]
    lo = connect(srv.pv("lohyst"))
    seq = []
    for v in (12, 8, 7, 6, 9, 10):
        put(lo, v)
        seq.append(ca.get_with_metadata(lo, ftype=dbr.TIME_LONG)["severity"])
    assert seq == [2, 2, 2, 0, 0, 2], "longout HIGH=10 HSV=MAJOR HYST=3"


def test_property_events(srv):
    chid = connect(srv.pv("prop"))
    col, _h = subscribe(chid, mask=PROPERTY, use_ctrl=True)
    assert col.wait_count(1, timeout=5)
    assert col.events[0]["units"] == "mm"
    put(chid, 5.0)  # a value change is not a property change
    assert epics.caput(srv.pv("prop.EGU"), "V", wait=True) == 1
    settle(col, 2)
    assert col.events[1]["units"] == "V"
    assert epics.caput(srv.pv("prop.HOPR"), 50.0, wait=True) == 1
    settle(col, 3)
    assert col.events[2]["upper_disp_limit"] == 50.0
    assert epics.caput(srv.pv("prop.PREC"), 4, wait=True) == 1
    settle(col, 4)
    assert col.events[3]["precision"] == 4
    assert col.count() == 4


def test_enum_monitor_native_and_string(srv):
    chid = connect(srv.pv("enum"))
    num, _h1 = subscribe(chid, mask=VALUE)
    txt, _h2 = subscribe(chid, mask=VALUE, ftype=dbr.STRING)
    assert num.wait_count(1, timeout=5) and txt.wait_count(1, timeout=5)
    for v in (2, 1, 1, 0):
        put(chid, v)
    assert settle(num, 4) == [0, 2, 1, 0]
    assert settle(txt, 4, quiet=0) == ["Zero", "Two", "One", "Zero"]


def test_dynamic_size_array_monitor(srv):
    chid = connect(srv.pv("wf"))
    col, _h = subscribe(chid, mask=VALUE, count=0)
    assert col.wait_count(1, timeout=5)
    put(chid, np.arange(5, dtype=float))
    put(chid, np.arange(10, dtype=float) * 2)
    settle(col, 3)
    vals = col.values()
    assert list(vals[1]) == [0.0, 1.0, 2.0, 3.0, 4.0], "count=0 monitors carry NORD elements"
    assert list(vals[2]) == [float(2 * i) for i in range(10)]
    assert [e["count"] for e in col.events[1:]] == [5, 10]


def test_one_megabyte_monitor(srv):
    chid = connect(srv.pv("bigwf"))
    col, _h = subscribe(chid, mask=VALUE, count=0)
    assert col.wait_count(1, timeout=10)
    data = np.random.default_rng(7).integers(0, 256, 1048576, dtype=np.uint8)
    assert ca.put(chid, data, wait=True, timeout=30) == 1
    assert col.wait_count(2, timeout=30)
    got = np.asarray(col.values()[1], dtype=np.uint8)
    assert got.shape == (1048576,) and np.array_equal(got, data)


def test_event_add_reply_and_cancel_raw(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("cancel"))
        sub1 = c.subscribe(ch, mask=raw.DBE_VALUE, dtype=raw.TIME_DOUBLE)
        m = c.recv_cmd(raw.EVENT_ADD)
        assert (m.dtype, m.count, m.p1, m.p2) == (20, 1, raw.ECA_NORMAL, sub1), \
            "EVENT_ADD update: dtype, count, p1=ECA status, p2=subid (§3)"
        d = raw.decode(m.dtype, m.count, m.payload)
        assert (d["status"], d["severity"]) == (17, 3)
        # cancel: reply is EVENT_ADD with postsize 0, same dtype/count, p1=sid, p2=subid
        c.send(raw.message(raw.EVENT_CANCEL, dtype=20, count=1, p1=ch["sid"], p2=sub1))
        m = c.recv_cmd(raw.EVENT_ADD)
        assert (m.postsize, m.dtype, m.count, m.p1, m.p2) == (0, 20, 1, ch["sid"], sub1)
        sub2 = c.subscribe(ch, mask=raw.DBE_VALUE, dtype=raw.DOUBLE)
        m = c.recv_cmd(raw.EVENT_ADD)
        assert m.p2 == sub2
        c.write(ch, [42.0])
        m = c.recv_cmd(raw.EVENT_ADD)
        assert m.p2 == sub2, f"update for cancelled subscription {sub1}: {m}"
        assert raw.decode(m.dtype, m.count, m.payload)["value"] == [42.0]
        # nothing else pending for the cancelled subscription
        try:
            extra = c.recv(timeout=0.5)
        except socket.timeout:
            extra = None
        assert extra is None, f"unexpected message after cancel: {extra}"


def test_clear_channel_stops_monitors(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c, raw.Circuit("127.0.0.1", srv.port) as w:
        ch = c.create(srv.pv("cancel"))
        sub = c.subscribe(ch, mask=raw.DBE_VALUE, dtype=raw.DOUBLE)
        assert c.recv_cmd(raw.EVENT_ADD).p2 == sub
        c.send(raw.message(raw.CLEAR_CHANNEL, p1=ch["sid"], p2=ch["cid"]))
        m = c.recv_cmd(raw.CLEAR_CHANNEL)
        assert (m.p1, m.p2) == (ch["sid"], ch["cid"]), "CLEAR_CHANNEL echoes sid/cid (§3)"
        wch = w.create(srv.pv("cancel"))
        assert w.write_notify(wch, [7.0]).p1 == raw.ECA_NORMAL
        time.sleep(0.3)
        c.send(raw.message(raw.ECHO))
        m = c.recv(timeout=5)
        assert m.cmd == raw.ECHO, f"no update may follow CLEAR_CHANNEL, got {m}"
