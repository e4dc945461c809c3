"""200 concurrent clients (separate TCP circuits), and a group of real libca clients in
separate processes, all served correctly by one server."""

import json
import subprocess
import time

import ca_raw as raw
from conftest import PYTHON, client_env, connect

from epics import ca

N_RAW = 200
N_PROC = 12
DB = ('record(ai, "$(P)shared") { }\n'
      + "".join('record(ao, "$(P)own%d") { }\n' % i for i in range(N_RAW)))


def test_200_concurrent_circuits(ioc):
    srv = ioc.start(DB)
    pfx = ioc.prefix
    fds0 = srv.fd_count()
    clients = []
    try:
        for i in range(N_RAW):
            c = raw.Circuit("127.0.0.1", srv.port, timeout=10, user=f"user{i}")
            shared = c.create(pfx + "shared", timeout=10)
            own = c.create(pfx + "own%d" % i, timeout=10)
            assert shared and own, f"client {i} could not create its channels"
            c.subscribe(shared, mask=raw.DBE_VALUE, dtype=raw.DOUBLE)
            clients.append((c, shared, own))
        assert srv.fd_count() >= fds0 + N_RAW, "every client has its own circuit"
        # all clients put to their own PV at once, then read the replies
        ioids = {}
        for i, (c, _s, own) in enumerate(clients):
            ioid = c.new_id()
            ioids[i] = ioid
            c.send(raw.message(raw.WRITE_NOTIFY, raw.encode_values(raw.DOUBLE, [float(i)]),
                               dtype=raw.DOUBLE, count=1, p1=own["sid"], p2=ioid))
        # a writer updates the shared PV 20 times
        w = connect(pfx + "shared")
        for k in range(1, 21):
            assert ca.put(w, float(k), wait=True, timeout=30) == 1
        for i, (c, _s, own) in enumerate(clients):
            updates, status = [], None
            deadline = time.monotonic() + 30
            while len(updates) < 21 or status is None:
                m = c.recv(timeout=max(0.1, deadline - time.monotonic()))
                if m.cmd == raw.EVENT_ADD:
                    updates.append(raw.decode(m.dtype, m.count, m.payload)["value"][0])
                elif m.cmd == raw.WRITE_NOTIFY:
                    assert m.p2 == ioids[i]
                    status = m.p1
            assert status == raw.ECA_NORMAL
            assert updates == [0.0] + [float(k) for k in range(1, 21)], \
                f"client {i} saw {updates}"
        for i, (c, _s, own) in enumerate(clients):
            assert c.read(own)[1]["value"] == [float(i)]
    finally:
        for c, _s, _o in clients:
            c.close()
    assert srv.alive()
    ok = ca.get(connect(pfx + "shared"))
    assert ok == 20.0


CLIENT = r"""
import json, sys, time, epics
pfx, idx = sys.argv[1], int(sys.argv[2])
seen = []
shared = epics.PV(pfx + "shared", callback=lambda value=None, **kw: seen.append(value))
own = epics.PV(pfx + "own%d" % idx)
assert shared.wait_for_connection(20) and own.wait_for_connection(20)
assert own.put(idx * 1.5, wait=True, timeout=30) == 1
t0 = time.time()
while 20.0 not in seen and time.time() - t0 < 60:
    time.sleep(0.02)
print(json.dumps({"own": own.get(use_monitor=False), "last": seen[-1] if seen else None}))
"""


def test_libca_clients_in_separate_processes(ioc):
    srv = ioc.start(DB)
    pfx = ioc.prefix
    procs = [subprocess.Popen([PYTHON, "-c", CLIENT, pfx, str(i)], env=client_env(srv.port),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(N_PROC)]
    try:
        w = connect(pfx + "shared", timeout=10)
        time.sleep(2.0)  # let the subprocesses subscribe (they wait for 20.0 anyway)
        for k in range(1, 21):
            assert ca.put(w, float(k), wait=True, timeout=30) == 1
        for i, p in enumerate(procs):
            out, err = p.communicate(timeout=90)
            assert p.returncode == 0, f"client {i}: {err[-2000:]}"
            res = json.loads(out.strip().splitlines()[-1])
            assert res == {"own": i * 1.5, "last": 20.0}, f"client {i}: {res}"
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait(10)
