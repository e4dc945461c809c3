"""Server and client restarts: clean shutdown on SIGTERM/SIGINT, libca reconnects to a restarted
server on the same port, crashed clients leave nothing behind, beacons (ca-protocol.md §2, §8)."""

import os
import signal
import socket
import struct
import subprocess
import time

import pytest

import ca_raw as raw
from conftest import PYTHON, Collector, client_env, connect, subscribe, wait_for

import epics
from epics import ca

DB = """
record(ao, "$(P)x") { field(VAL, "1") field(PINI, "YES") }
record(ai, "$(P)y") { }
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_cleanly(ioc, sig):
    srv = ioc.start(DB)
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(ioc.prefix + "x")
        c.subscribe(ch)
        c.recv_cmd(raw.EVENT_ADD)
        srv.signal(sig)
        srv.proc.wait(10)
        assert srv.proc.returncode == 0, f"exit code after {sig.name}: {srv.proc.returncode}"
        with pytest.raises(raw.ClosedError):
            while True:
                c.recv(timeout=5)


@pytest.mark.parametrize("how", ["sigterm", "sigkill"])
def test_client_reconnects_after_server_restart(ioc, how):
    srv = ioc.start(DB)
    name = ioc.prefix + "x"
    conn_events = []
    pv = epics.PV(name, auto_monitor=True,
                  connection_callback=lambda pvname=None, conn=None, **kw: conn_events.append(conn))
    assert pv.wait_for_connection(5)
    col = Collector()
    pv.add_callback(col)
    assert pv.put(5.0, wait=True) == 1
    assert col.wait_value(lambda v: v == 5.0, 5)

    if how == "sigterm":
        assert srv.stop() == 0
    else:
        srv.proc.kill()
        srv.proc.wait(10)
    assert wait_for(lambda: conn_events and conn_events[-1] is False, 10), \
        "libca must see the circuit close"
    srv.start()  # same port, immediately: needs address reuse
    assert wait_for(lambda: pv.connected and conn_events[-1] is True, 30), \
        "pyepics did not reconnect to the restarted server"
    # the new server starts from the .db again (PINI VAL=1) and the monitor resumes
    assert col.wait_value(lambda v: v == 1.0, 10), f"monitor did not resume: {col.values()}"
    n = col.count()
    assert pv.put(7.0, wait=True) == 1
    assert col.wait_value(lambda v: v == 7.0, 5)
    assert col.count() >= n + 1
    assert pv.get(use_monitor=False) == 7.0
    pv.disconnect()


def test_crashing_clients_leave_no_residue(ioc):
    srv = ioc.start(DB)
    name = ioc.prefix + "x"
    # warm up once so lazily opened descriptors exist before the baseline
    with raw.Circuit("127.0.0.1", srv.port) as c:
        c.create(name)
    time.sleep(0.2)
    fds0 = srv.fd_count()
    code = (
        "import os, epics, sys\n"
        "pv = epics.PV(sys.argv[1])\n"
        "assert pv.wait_for_connection(10)\n"
        "pv.add_callback(lambda **kw: None)\n"
        "assert pv.put(float(sys.argv[2]), wait=True) == 1\n"
        "print('ok', flush=True)\n"
        "os._exit(0)  # no clean channel clear\n")
    procs = [subprocess.Popen([PYTHON, "-c", code, name, str(i)], env=client_env(srv.port),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(6)]
    for p in procs:
        out, err = p.communicate(timeout=60)
        assert "ok" in out, f"client failed: {err[-1500:]}"
    # raw clients that vanish with RST in the middle of a subscription
    for i in range(30):
        c = raw.Circuit("127.0.0.1", srv.port)
        ch = c.create(name)
        c.subscribe(ch)
        c.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        c.close()
    assert wait_for(lambda: srv.fd_count() <= fds0 + 1, 10), \
        f"descriptors leaked: {fds0} before, {srv.fd_count()} after 36 dead clients"
    with raw.Circuit("127.0.0.1", srv.port) as c:
        assert c.read(c.create(name))[1]["value"][0] in [float(i) for i in range(6)]


def test_beacons(ioc):
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(0.2)
    bport = sink.getsockname()[1]
    srv = ioc.start(DB, extra_env={"EPICS_CAS_BEACON_ADDR_LIST": f"127.0.0.1:{bport}",
                                   "EPICS_CAS_BEACON_PERIOD": "1.0"})
    # beacons until the steady period shows (the last more than 5 s after the first), however
    # long a loaded machine takes to get there; the deadline only ends a server that stays silent
    beacons = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (len(beacons) >= 8 and beacons[-1][0] - beacons[0][0] > 5.0):
        try:
            pkt, _ = sink.recvfrom(1024)
        except socket.timeout:
            continue
        beacons.append((time.monotonic(), pkt))
    sink.close()
    assert len(beacons) >= 8 and beacons[-1][0] - beacons[0][0] > 5.0, \
        f"beacons stopped: {len(beacons)} in 60 s"
    ids = []
    for _, pkt in beacons:
        assert len(pkt) == 16, "a beacon is one bare header"
        cmd, size, dtype, count, p1, p2 = struct.unpack(">HHHHII", pkt)
        assert (cmd, size, dtype, count) == (raw.RSRV_IS_UP, 0, 13, srv.port), \
            "RSRV_IS_UP: dtype=13 (minor), count=TCP port (§1 cmd 13)"
        assert p2 in (0, 0x7F000001)
        ids.append(p1)
    assert all(0 <= b - a <= 1 for a, b in zip(ids, ids[1:])), f"beacon ids {ids}"
    assert ids[-1] >= 3
    times = [t for t, _ in beacons]
    gaps = [b - a for a, b in zip(times, times[1:])]
    # fast start (0.02 s doubling) then the configured period of 1 s. The arrival times are this
    # client's: a late read stretches one gap (and shortens the next), so the fast start is most
    # of the first gaps being short, and the period the median of the gaps after 2 s
    assert sum(1 for g in gaps[:5] if g < 0.5) >= 3, f"no fast start: gaps {gaps}"
    late = sorted(g for t, g in zip(times[1:], gaps) if t - times[0] > 2.0)
    assert len(late) >= 3 and 0.6 < late[len(late) // 2] < 1.6, f"steady period should be 1 s: {gaps}"


def test_restart_changes_nothing_for_other_servers(ioc):
    a = ioc.start(DB, macros=f"P={ioc.prefix}a:")
    b = ioc.start(DB, macros=f"P={ioc.prefix}b:")
    pa, pb = connect(ioc.prefix + "a:x"), connect(ioc.prefix + "b:x")
    col, _h = subscribe(pb)
    assert col.wait_count(1, 5)
    a.stop()
    for i in range(5):
        assert ca.put(pb, float(10 + i), wait=True) == 1
    assert col.wait_value(lambda v: v == 14.0, 5)
    a.start()
    assert wait_for(lambda: ca.isConnected(pa), 30)
    assert ca.get(pa) == 1.0 and ca.get(pb) == 14.0
    assert os.path.exists(f"/proc/{b.proc.pid}")
