"""Malformed input over raw sockets, and slow consumers: each bad request gets the reply the spec
prescribes (ca-protocol.md §1, §3) and the server keeps serving everyone else (§7)."""

import random
import socket
import struct
import threading
import time

import pytest

import ca_raw as raw
from conftest import connect, subscribe, wait_for

import epics
from epics import ca

DB = """
record(ai, "$(P)a") { field(VAL, "1.5") field(PINI, "YES") }
record(ai, "$(P)probe") { }
record(waveform, "$(P)wf") { field(FTVL, "DOUBLE") field(NELM, "50000") }
record(waveform, "$(P)fast") { field(FTVL, "DOUBLE") field(NELM, "20000") }
"""


@pytest.fixture
def srv(ioc):
    s = ioc.start(DB)
    s.pv = lambda suffix: ioc.prefix + suffix
    return s


def assert_healthy(srv):
    """The server still answers a fresh raw circuit and pyepics (a different client)."""
    assert srv.alive(), f"server died: {srv.stderr()[-2000:]}"
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("a"))
        assert ch is not None
        assert c.read(ch)[1]["value"] == [1.5]
    assert epics.caget(srv.pv("a"), use_monitor=False, timeout=5) == 1.5


def test_echo_and_read_sync(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        c.send(raw.message(raw.ECHO, b"12345678", p1=7, p2=9))
        m = c.recv_cmd(raw.ECHO)
        assert (m.postsize, m.p1, m.p2, m.payload) == (8, 7, 9, b"12345678"), \
            "ECHO returns header and payload unchanged"
        c.send(raw.message(raw.READ_SYNC, p1=3, p2=4))
        m = c.recv_cmd(raw.READ_SYNC)
        assert (m.p1, m.p2) == (3, 4)


def test_message_split_into_single_bytes(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("a"))
        req = raw.message(raw.READ_NOTIFY, dtype=raw.DOUBLE, count=1, p1=ch["sid"], p2=4242)
        for b in req[:-1]:
            c.send(bytes([b]))
            time.sleep(0.002)
        with pytest.raises(socket.timeout):
            c.recv(timeout=0.3)  # incomplete message: nothing yet
        c.send(req[-1:])
        m = c.recv_cmd(raw.READ_NOTIFY)
        assert m.p2 == 4242 and raw.decode(m.dtype, m.count, m.payload)["value"] == [1.5]
        # a CREATE_CHAN body split across writes
        name = srv.pv("probe").encode() + b"\0"
        msg = raw.message(raw.CREATE_CHAN, name, p1=99, p2=13)
        c.send(msg[:20])
        time.sleep(0.2)
        c.send(msg[20:])
        m = c.recv_cmd(raw.CREATE_CHAN)
        assert m.p1 == 99


def test_truncated_messages_then_disconnect(srv):
    pieces = [b"\x00\x0f\x00", raw.header(raw.CREATE_CHAN, 64, 0, 0, 5, 13) + b"abc",
              raw.header(raw.WRITE, 0xFFFF, 6, 0, 1, 1)[:18],
              raw.header(raw.ECHO, 0xFFFF, 0, 0, 0, 0, extended=False) + b"\0" * 4]
    for abort in (False, True):
        for p in pieces:
            c = raw.Circuit("127.0.0.1", srv.port)
            c.send(p)
            if abort:  # RST instead of FIN
                c.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            c.close()
    time.sleep(0.2)
    assert_healthy(srv)


@pytest.mark.parametrize("case", ["echo_size_4", "create_name_unpadded"])
def test_misaligned_message_rejected(srv, case):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        if case == "echo_size_4":
            bad = raw.header(raw.ECHO, 4) + b"abcd"
        else:
            name = srv.pv("a").encode() + b"\0"
            if len(name) % 8 == 0:
                name += b"\0"
            bad = raw.header(raw.CREATE_CHAN, len(name), 0, 0, 5, 13) + name
        c.send(bad)
        got = c.expect_closed()
        errors = [m for m in got if m.cmd == raw.ERROR]
        assert errors, f"expected ERROR before close (§1), got {got}"
        assert errors[0].p2 == raw.ECA_INTERNAL
        assert errors[0].payload[:16] == bad[:16], "ERROR embeds the failing header"
    assert_healthy(srv)


def test_unknown_command(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        bad = raw.message(0x7777, b"x" * 8, p1=1, p2=2)
        c.send(bad)
        got = c.expect_closed()
        assert [m.cmd for m in got] == [raw.ERROR], f"one ERROR then close (§3), got {got}"
        assert (got[0].p1, got[0].p2) == (0xFFFFFFFF, raw.ECA_INTERNAL)
        assert got[0].payload[:16] == bad[:16]
    assert_healthy(srv)


@pytest.mark.parametrize("cmd", ["READ_NOTIFY", "WRITE", "WRITE_NOTIFY", "EVENT_ADD",
                                 "EVENT_CANCEL", "CLEAR_CHANNEL"])
def test_bad_sid(srv, cmd):
    sid = 0xDEADBEEF
    with raw.Circuit("127.0.0.1", srv.port) as c:
        c.create(srv.pv("a"))  # a real channel exists, just not this sid
        if cmd == "READ_NOTIFY":
            bad = raw.message(raw.READ_NOTIFY, dtype=raw.DOUBLE, count=1, p1=sid, p2=1)
        elif cmd == "WRITE":
            bad = raw.message(raw.WRITE, raw.encode_values(raw.DOUBLE, [1.0]), dtype=raw.DOUBLE,
                              count=1, p1=sid, p2=1)
        elif cmd == "WRITE_NOTIFY":
            bad = raw.message(raw.WRITE_NOTIFY, raw.encode_values(raw.DOUBLE, [1.0]),
                              dtype=raw.DOUBLE, count=1, p1=sid, p2=1)
        elif cmd == "EVENT_ADD":
            bad = raw.message(raw.EVENT_ADD, struct.pack(">fffHH", 0, 0, 0, 1, 0),
                              dtype=raw.DOUBLE, count=1, p1=sid, p2=1)
        elif cmd == "EVENT_CANCEL":
            bad = raw.message(raw.EVENT_CANCEL, dtype=raw.DOUBLE, count=1, p1=sid, p2=1)
        else:
            bad = raw.message(raw.CLEAR_CHANNEL, p1=sid, p2=1)
        c.send(bad)
        e = c.recv(timeout=5)
        assert e.cmd == raw.ERROR, f"bad sid: ERROR first (§3), got {e}"
        assert (e.p1, e.p2) == (0xFFFFFFFF, raw.ECA_INTERNAL), \
            f"bad sid: ERROR ECA_INTERNAL 'Bad Resource ID' with p1=~0 (§3), got {e} {e.error_text()!r}"
        assert e.payload[:16] == bad[:16]
        assert "Bad Resource ID" in e.error_text(), e.error_text()
        # RSRV then closes the circuit; the spec only prescribes the ERROR, so a server that
        # keeps the circuit must keep it coherent: the next ECHO is answered.
        try:
            c.send(raw.message(raw.ECHO))
            rest = []
            while True:
                m = c.recv(timeout=5)
                rest.append(m)
                if m.cmd == raw.ECHO:
                    break
            assert all(m.cmd == raw.WRITE_NOTIFY and m.p1 != raw.ECA_NORMAL for m in rest[:-1]), \
                f"no data reply may follow a bad-sid request: {rest}"
        except (raw.ClosedError, BrokenPipeError, ConnectionResetError):
            pass
    assert_healthy(srv)


def test_unknown_subscription_id(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("a"))
        bad = raw.message(raw.EVENT_CANCEL, dtype=raw.DOUBLE, count=1, p1=ch["sid"], p2=31337)
        c.send(bad)
        m = c.recv_cmd(raw.ERROR)
        assert (m.p1, m.p2) == (ch["cid"], raw.ECA_BADMONID), "unknown subid: ECA_BADMONID (§3)"
        assert m.payload[:16] == bad[:16]
    assert_healthy(srv)


@pytest.mark.parametrize("cmd", [raw.READ_NOTIFY, raw.EVENT_ADD])
def test_bad_dbr_type_closes_circuit(srv, cmd):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("a"))
        body = struct.pack(">fffHH", 0, 0, 0, 1, 0) if cmd == raw.EVENT_ADD else b""
        c.send(raw.message(cmd, body, dtype=99, count=1, p1=ch["sid"], p2=5))
        got = c.expect_closed()
        assert all(m.cmd == raw.ERROR for m in got), f"no data reply for DBR type 99: {got}"
    assert_healthy(srv)


def test_oversized_request_is_drained(ioc):
    srv = ioc.start(DB, extra_env={"EPICS_CA_AUTO_ARRAY_BYTES": "NO",
                                   "EPICS_CA_MAX_ARRAY_BYTES": "100000"})
    srv.pv = lambda suffix: ioc.prefix + suffix
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("wf"))
        body = raw.encode_values(raw.DOUBLE, [3.0] * 25000)  # 200000 bytes > limit
        req = raw.header(raw.WRITE, len(body), raw.DOUBLE, 25000, ch["sid"], ch["cid"],
                         extended=True) + body
        c.send(req)
        m = c.recv_cmd(raw.ERROR, timeout=10)
        assert m.p2 == raw.ECA_TOLARGE, f"oversized request: ECA_TOLARGE (§8), got {m}"
        assert m.error_request()[:4] == (raw.WRITE, len(body), raw.DOUBLE, 25000)
        # the body was drained: the circuit still parses the next message correctly
        assert c.echo(timeout=10).cmd == raw.ECHO
        assert c.read(ch, count=1)[1]["value"] == [0.0], "the oversized write changed nothing"
        small = raw.encode_values(raw.DOUBLE, [2.0] * 100)
        c.send(raw.message(raw.WRITE, small, dtype=raw.DOUBLE, count=100, p1=ch["sid"],
                           p2=ch["cid"]))
        assert c.read(ch, count=2)[1]["value"] == [2.0, 2.0]
    assert_healthy(srv)


def test_absurd_declared_size(srv):
    rss0 = srv.rss_kb()
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("wf"))
        c.send(raw.header(raw.WRITE, 0x7FFFFFF8, raw.DOUBLE, 0x0FFFFFFF, ch["sid"], ch["cid"],
                          extended=True) + b"\0" * 65536)
        try:
            m = c.recv(timeout=1.0)
            assert m.cmd == raw.ERROR and m.p2 == raw.ECA_TOLARGE, m
        except (socket.timeout, raw.ClosedError):
            pass  # waiting for the body or closing are acceptable; crashing is not
        assert_healthy(srv)
        assert srv.rss_kb() - rss0 < 256 * 1024, "declared size must not be allocated eagerly"
    assert_healthy(srv)


def test_odd_bodies(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        # empty name: no channel, circuit goes on
        c.send(raw.header(raw.CREATE_CHAN, 0, 0, 0, 11, 13))
        # name without NUL filling the whole padded body
        c.send(raw.message(raw.CREATE_CHAN, b"ABCDEFGH", p1=12, p2=13))
        got = []
        while True:
            m = c.recv(timeout=5)
            if m.cmd == raw.CREATE_CH_FAIL:
                got.append(m.p1)
                if 12 in got:
                    break
            else:
                assert m.cmd != raw.CREATE_CHAN, f"no channel may be created: {m}"
        assert 12 in got
        assert c.echo().cmd == raw.ECHO
    # WRITE whose count exceeds its payload: must not read past the message
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("wf"))
        c.send(raw.message(raw.WRITE, raw.encode_values(raw.DOUBLE, [1.0]), dtype=raw.DOUBLE,
                           count=5000, p1=ch["sid"], p2=ch["cid"]))
        try:
            c.echo(timeout=3)
        except (raw.ClosedError, socket.timeout, AssertionError):
            pass
    assert_healthy(srv)


def test_seeded_garbage(srv):
    """200 circuits of random (mostly well-framed) messages; each ends with EOF."""
    rng = random.Random(20240601)
    with raw.Circuit("127.0.0.1", srv.port) as probe:
        sid = probe.create(srv.pv("probe"))["sid"]
    cmds = [0, 1, 2, 3, 4, 6, 8, 9, 10, 12, 15, 18, 19, 20, 21, 23, 27, 99, 0xFFFF]
    for case in range(200):
        c = raw.Circuit("127.0.0.1", srv.port, handshake=case % 2 == 0)
        data = b""
        for _ in range(rng.randint(1, 6)):
            size = rng.choice([0, 8, 16, 40, rng.randrange(0, 300)])
            if rng.random() < 0.8:
                size = raw.pad8(size)
            body = bytes(rng.randrange(256) for _ in range(size))
            dtype = rng.choice([0, 6, 14, 34, 38, rng.randrange(0x10000)])
            count = rng.choice([0, 1, 2, 0xFFFF, rng.randrange(0x10000)])
            p1 = rng.choice([sid, 0, 0xFFFFFFFF, rng.randrange(1 << 32)])
            data += raw.header(rng.choice(cmds), size, dtype, count, p1, rng.randrange(1 << 32),
                               extended=False) + body
        if rng.random() < 0.2:
            data = data[:rng.randrange(len(data) + 1)]
        try:
            c.send(data)
            c.sock.shutdown(socket.SHUT_WR)
            c.expect_closed(timeout=5)  # after our EOF the server must close too
        except (ConnectionResetError, BrokenPipeError):
            pass
        finally:
            c.close()
    assert_healthy(srv)


def test_udp_search_reply_and_garbage(srv):
    # garbage datagrams first
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rng = random.Random(7)
    for n in (0, 1, 15, 16, 17, 100, 1400):
        s.sendto(bytes(rng.randrange(256) for _ in range(n)), ("127.0.0.1", srv.port))
    s.sendto(raw.header(raw.SEARCH, 0xFFF0, 10, 13, 1, 1) + b"abc", ("127.0.0.1", srv.port))
    s.close()
    found, missing = srv.pv("a"), srv.pv("does_not_exist")
    dgrams = raw.udp_search(srv.port, [missing, found, srv.pv("a.EGU")])
    msgs = [m for d in dgrams for m in d]
    search = [m for m in msgs if m.cmd == raw.SEARCH]
    assert sorted(m.p2 for m in search) == [1001, 1002], f"replies for the two known names: {msgs}"
    for m in search:
        assert (m.postsize, m.dtype, m.count) == (8, srv.port, 0)
        assert m.p1 in (0xFFFFFFFF, 0x7F000001)
        assert struct.unpack(">H", m.payload[:2])[0] == 13
    assert not [m for m in msgs if m.cmd == raw.NOT_FOUND], "never NOT_FOUND over UDP (§2)"
    first = dgrams[0][0]
    assert (first.cmd, first.dtype, first.count, first.p1) == (raw.VERSION, 1, 13, 0x1234), \
        "reply datagram starts with VERSION(dtype=1, count=13, p1=client seq)"
    assert_healthy(srv)


def test_tcp_search(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        c.send(raw.message(raw.SEARCH, srv.pv("a").encode() + b"\0", dtype=10, count=13,
                           p1=55, p2=55))
        m = c.recv(timeout=5)
        assert (m.cmd, m.dtype, m.count, m.p1, m.p2) == (raw.SEARCH, srv.port, 0, 0xFFFFFFFF, 55)
        c.send(raw.message(raw.SEARCH, b"nope:nothing\0", dtype=10, count=13, p1=56, p2=56))
        m = c.recv(timeout=5)
        assert (m.cmd, m.p2) == (raw.NOT_FOUND, 56)
        c.send(raw.message(raw.SEARCH, b"nope:nothing\0", dtype=5, count=13, p1=57, p2=57))
        assert c.echo().cmd == raw.ECHO, "DONT_REPLY search for a missing name gets no answer"


class FirstElement:
    """Monitor sink that keeps only (count, first element) of the latest update."""

    def __init__(self):
        self.n = 0
        self.last = None

    def __call__(self, value=None, **kw):
        self.n += 1
        self.last = (len(value), float(value[0])) if len(value) else (0, None)

    def wait_count(self, n, timeout):
        return wait_for(lambda: self.n >= n, timeout)


def test_stalled_client_does_not_delay_others(srv):
    """A client that subscribes to a fast PV and never reads must not hold up anyone else (§7):
    while it stays stalled, another client's 800 large writes all go through, the clients that do
    read get every answer and the final values, the server's memory stays bounded (the stalled
    client's updates are coalesced, not queued without end), and the stalled client keeps its
    circuit: when it reads at last it gets its updates in order, ending with the latest value.
    No step is timed against the wall clock: every wait is for the behaviour, with a deadline that
    only ends a test whose server hangs (a server that blocked on the stalled client would)."""
    deadline = 60  # [s]
    stalled = raw.Circuit("127.0.0.1", srv.port, rcvbuf=4096)
    fch = stalled.create(srv.pv("fast"))
    stalled_subid = stalled.subscribe(fch, mask=raw.DBE_VALUE, dtype=raw.DOUBLE, count=20000)
    # from here on the stalled client does not read until the end of the test

    fast = connect(srv.pv("fast"))
    probe = connect(srv.pv("probe"))
    fast_col = FirstElement()
    _h1 = ca.create_subscription(fast, callback=fast_col, count=0)
    probe_col, _h2 = subscribe(probe)
    assert fast_col.wait_count(1, deadline) and probe_col.wait_count(1, deadline)
    rss0 = srv.rss_kb()

    n_writes, nelm = 800, 20000
    rest = raw.encode_values(raw.DOUBLE, [0.5] * (nelm - 1))
    state = {"done": False, "error": None}

    def writer():
        try:
            with raw.Circuit("127.0.0.1", srv.port, timeout=deadline) as w:
                ch = w.create(srv.pv("fast"), timeout=deadline)
                hdr = raw.header(raw.WRITE, nelm * 8, raw.DOUBLE, nelm, ch["sid"], ch["cid"],
                                 extended=True)
                for i in range(1, n_writes + 1):
                    w.send(hdr + struct.pack(">d", float(i)) + rest)
                # ECHO answered: the server has handled every write before it
                assert w.echo(timeout=3 * deadline).cmd == raw.ECHO
        except Exception as e:  # reported by the main thread
            state["error"] = e
        state["done"] = True

    t = threading.Thread(target=writer, daemon=True)
    t.start()
    # the probe client is served all along: each put is confirmed and read back, in order
    i = 0
    while not state["done"] or i < 20:
        i += 1
        assert ca.put(probe, float(i), wait=True, timeout=deadline) == 1, f"put {i} not confirmed"
        assert ca.get(probe, timeout=deadline) == float(i)
        if i > 2000:
            break
    t.join(3 * deadline)
    assert not t.is_alive(), "the writer's 800 writes were not all handled"
    assert state["error"] is None, f"writer failed: {state['error']!r}"
    assert probe_col.wait_value(lambda v: v == float(i), deadline), "probe monitor fell behind"
    assert wait_for(lambda: fast_col.last == (nelm, float(n_writes)), deadline), \
        "the monitoring client never saw the final value of the fast PV"
    growth_mb = (srv.rss_kb() - rss0) / 1024
    assert growth_mb < 64, f"server RSS grew {growth_mb:.0f} MB: updates for the stalled " \
                           f"client must be coalesced, not queued without bound"
    ca.clear_subscription(_h1[2])

    # the stalled client was neither dropped nor fed every update: reading now, it gets its
    # updates in order, far fewer than the writes, and the last one is the final value
    firsts = []
    try:
        while not firsts or firsts[-1] != float(n_writes):
            m = stalled.recv(timeout=deadline)
            if m.cmd == raw.EVENT_ADD and m.p2 == stalled_subid:
                assert m.count == nelm, m
                firsts.append(struct.unpack_from(">d", m.payload, 0)[0])
    except raw.ClosedError:
        pytest.fail(f"the server dropped the stalled client after {len(firsts)} updates "
                    f"(last {firsts[-1:]}); its updates should be coalesced instead")
    assert firsts == sorted(firsts), f"updates out of order: {firsts}"
    assert len(firsts) < n_writes, f"{len(firsts)} updates: none coalesced"
    assert stalled.echo(timeout=deadline).cmd == raw.ECHO
    stalled.close()
    assert_healthy(srv)
