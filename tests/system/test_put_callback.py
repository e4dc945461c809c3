"""Put-callback (WRITE_NOTIFY): completion after processing, reply fields, pipelining, failures
always answered (ca-protocol.md §3 cmd 19; records.md §0)."""

import threading
import time

import numpy as np
import pytest

import ca_raw as raw
from conftest import connect, module_server

import epics
from epics import ca, dbr

DB = """
record(ai, "$(P)ai") { }
record(ao, "$(P)ao") { field(DRVH, "10") field(DRVL, "0") }
record(mbbo, "$(P)mbbo") { field(ZRST, "Zero") field(ONST, "One") }
record(waveform, "$(P)wf") { field(FTVL, "LONG") field(NELM, "1000") }
record(longout, "$(P)lo") { }
record(ai, "$(P)proc") { }
record(stringout, "$(P)so") { }
"""


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    yield from module_server(tmp_path_factory, DB, name="putcb")


@pytest.fixture
def rawc(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        yield c


def test_pyepics_put_wait_returns_one_and_value_is_applied(srv):
    for name, value, expect in (("ai", 3.5, 3.5), ("ao", 25.0, 10.0), ("lo", -12, -12),
                                ("so", "done", "done")):
        chid = connect(srv.pv(name))
        assert ca.put(chid, value, wait=True, timeout=10) == 1, f"{name}: put-callback timed out"
        assert ca.get(chid) == expect
    pv = epics.PV(srv.pv("mbbo"), auto_monitor=False)
    assert pv.wait_for_connection(5)
    assert pv.put("One", wait=True) == 1 and pv.get(use_monitor=False) == 1
    chid = connect(srv.pv("wf"))
    assert ca.put(chid, np.arange(1000, dtype=np.int32), wait=True) == 1
    assert list(ca.get(chid)[-3:]) == [997, 998, 999]


def test_pyepics_put_callback_function(srv):
    done = threading.Event()
    seen = {}

    def cb(pvname=None, **kw):
        seen["pvname"] = pvname
        seen["value_then"] = None
        done.set()

    pv = epics.PV(srv.pv("ai"), auto_monitor=False)
    assert pv.wait_for_connection(5)
    pv.put(77.25, callback=cb)
    deadline = time.time() + 10
    while not done.is_set() and time.time() < deadline:
        epics.poll(0.01)
    assert done.is_set(), "put callback never called"
    assert seen["pvname"] == srv.pv("ai")
    assert pv.get(use_monitor=False) == 77.25


def test_write_notify_reply_fields(srv, rawc):
    ch = rawc.create(srv.pv("lo"))
    ioid = rawc.new_id()
    rawc.send(raw.message(raw.WRITE_NOTIFY, raw.encode_values(raw.LONG, [42]), dtype=raw.LONG,
                          count=1, p1=ch["sid"], p2=ioid))
    m = rawc.recv_cmd(raw.WRITE_NOTIFY)
    assert (m.cmd, m.postsize, m.dtype, m.count, m.p1, m.p2) == \
        (raw.WRITE_NOTIFY, 0, raw.LONG, 1, raw.ECA_NORMAL, ioid)
    assert rawc.read(ch)[1]["value"] == [42]
    # non-native request type: the server converts, reply echoes the request type/count
    ioid = rawc.new_id()
    rawc.send(raw.message(raw.WRITE_NOTIFY, raw.encode_values(raw.STRING, ["-9"]),
                          dtype=raw.STRING, count=1, p1=ch["sid"], p2=ioid))
    m = rawc.recv_cmd(raw.WRITE_NOTIFY)
    assert (m.dtype, m.count, m.p1, m.p2) == (raw.STRING, 1, raw.ECA_NORMAL, ioid)
    assert rawc.read(ch)[1]["value"] == [-9]


def test_short_string_payload_like_libca(srv, rawc):
    """libca sends a single DBR_STRING as strlen+1 bytes padded to 8, not 40 (tcpiiu.cpp)."""
    ch = rawc.create(srv.pv("so"))
    for text in ("hi", "abcdefg", "x" * 20):
        body = text.encode() + b"\0"
        ioid = rawc.new_id()
        rawc.send(raw.message(raw.WRITE_NOTIFY, body, dtype=raw.STRING, count=1, p1=ch["sid"],
                              p2=ioid))
        m = rawc.recv_cmd(raw.WRITE_NOTIFY)
        assert (m.p1, m.p2) == (raw.ECA_NORMAL, ioid), f"short DBR_STRING put '{text}': {m}"
        assert rawc.read(ch)[1]["value"] == [text]
        rawc.send(raw.message(raw.WRITE, (text + "!").encode() + b"\0", dtype=raw.STRING,
                              count=1, p1=ch["sid"], p2=ch["cid"]))
        assert rawc.read(ch)[1]["value"] == [text + "!"]


def test_pipelined_write_notifies_all_answered(srv, rawc):
    ch = rawc.create(srv.pv("lo"))
    ioids = []
    data = b""
    for i in range(50):
        ioid = rawc.new_id()
        ioids.append(ioid)
        data += raw.message(raw.WRITE_NOTIFY, raw.encode_values(raw.LONG, [i]), dtype=raw.LONG,
                            count=1, p1=ch["sid"], p2=ioid)
    rawc.send(data)
    replies = [rawc.recv_cmd(raw.WRITE_NOTIFY, timeout=10) for _ in ioids]
    assert sorted(m.p2 for m in replies) == sorted(ioids)
    assert all(m.p1 == raw.ECA_NORMAL for m in replies)
    assert rawc.read(ch)[1]["value"] == [49], "puts are applied in order"


def test_failed_put_callbacks_are_answered(srv, rawc):
    # read-only field: the reply still comes, with ECA_NOWTACCESS
    name = rawc.create(srv.pv("lo.NAME"))
    assert name["access"] == 1
    m = rawc.write_notify(name, ["other"], dtype=raw.STRING)
    assert m.p1 == raw.ECA_NOWTACCESS
    # unconvertible value: ECA_PUTFAIL, value unchanged
    mb = rawc.create(srv.pv("mbbo"))
    assert rawc.write_notify(mb, ["Zero"], dtype=raw.STRING).p1 == raw.ECA_NORMAL
    assert rawc.write_notify(mb, ["Seven"], dtype=raw.STRING).p1 == raw.ECA_PUTFAIL
    assert rawc.read(mb)[1]["value"] == [0]
    # the circuit is fine afterwards
    assert rawc.echo().cmd == raw.ECHO


def test_put_to_proc_processes_record(srv):
    chid = connect(srv.pv("proc"))
    md = ca.get_with_metadata(chid, ftype=dbr.TIME_DOUBLE)
    assert (md["severity"], md["status"]) == (3, 17), "never processed -> UDF/INVALID"
    before = time.time()
    assert epics.caput(srv.pv("proc.PROC"), 1, wait=True) == 1
    md = ca.get_with_metadata(chid, ftype=dbr.TIME_DOUBLE)
    assert (md["severity"], md["status"]) == (0, 0), "processing a soft ai with VAL=0 clears UDF"
    assert md["timestamp"] >= before - 1.0


def test_concurrent_put_callbacks_from_two_circuits(srv):
    results = {}

    def worker(tag, values):
        with raw.Circuit("127.0.0.1", srv.port) as c:
            ch = c.create(srv.pv("ai"))
            results[tag] = [c.write_notify(ch, [v], dtype=raw.DOUBLE).p1 for v in values]

    threads = [threading.Thread(target=worker, args=(t, [float(i) for i in range(100)]))
               for t in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert results.get("a") == [raw.ECA_NORMAL] * 100
    assert results.get("b") == [raw.ECA_NORMAL] * 100
