"""The Channel Access repeater (`beamctl ca-repeater`, or beamctl invoked as `caRepeater`):
registration and REPEATER_CONFIRM, beacons fanned out to every registered client with the server's
address filled in, a second repeater exiting quietly, and what a real libca client (pyepics) sees:
no "caRepeater" warning and the server's beacons (its beacon period becomes known).
ca-protocol.md §1, §8; EPICS base's repeater.cpp and caRepeater.cpp.

Waits are for the behaviour, with deadlines that only end a hung test (DEADLINE); the short
timeouts left are for things that must NOT arrive."""

import json
import os
import random
import signal
import socket
import struct
import subprocess
import time
from pathlib import Path

import pytest

import ca_raw as raw
from conftest import (BEAMCTL, PYTHON, REPEATER_PORT, SERVER_PORTS, IocServer, client_env,
                      require_binary)

REPEATER_CONFIRM, REPEATER_REGISTER = 17, 24
LOOPBACK = 0x7F000001

DB = 'record(ai, "$(P)x") { field(VAL, "4.25") field(PINI, "YES") }\n'
DEADLINE = 30.0  # [s]


def free_udp_port():
    """A UDP (and TCP) port that nothing holds now and that the conftest pool does not use."""
    rng = random.Random()
    while True:
        p = rng.randrange(20000, 32000)
        if p in SERVER_PORTS or p == REPEATER_PORT:
            continue
        u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            u.bind(("0.0.0.0", p))
            return p
        except OSError:
            continue
        finally:
            u.close()


class RepeaterProc(IocServer):
    """`beamctl ca-repeater` with EPICS_CA_REPEATER_PORT=port (same life cycle as IocServer)."""

    def __init__(self, workdir, port, name="repeater"):
        super().__init__(workdir, [], 0, name=name,
                         extra_env={"EPICS_CA_REPEATER_PORT": str(port), "BEAMCTL_LOG": "ca.repeater=debug"})
        self.repeater_port = port

    def argv(self):
        return [str(BEAMCTL), "ca-repeater"]


@pytest.fixture
def repeater(tmp_path):
    require_binary()
    rep = RepeaterProc(tmp_path, free_udp_port())
    try:
        yield rep.start()
    finally:
        rep.kill()


def udp_socket():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("0.0.0.0", 0))
    s.settimeout(0.2)
    return s


def recv_until(sock, pred, timeout=DEADLINE):
    """The first datagram for which pred(bytes) is true, or None after timeout seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            pkt = sock.recv(65536)
        except socket.timeout:
            continue
        if pred(pkt):
            return pkt
    return None


def cmd_of(pkt):
    return struct.unpack(">H", pkt[:2])[0] if len(pkt) >= 2 else None


def register(sock, port):
    sock.sendto(raw.header(REPEATER_REGISTER, p2=LOOPBACK), ("127.0.0.1", port))
    return recv_until(sock, lambda p: cmd_of(p) == REPEATER_CONFIRM)


def test_register_confirm_and_beacon_fan_out(repeater):
    port = repeater.repeater_port
    assert repeater.ready_line == f"ready: CA repeater on udp 0.0.0.0:{port}"
    a, b, server = udp_socket(), udp_socket(), udp_socket()
    try:
        for s in (a, b):
            confirm = register(s, port)
            assert confirm is not None, f"no REPEATER_CONFIRM within {DEADLINE:.0f} s"
            assert confirm == raw.header(REPEATER_CONFIRM, p2=LOOPBACK), confirm.hex()
        # a server on this host announcing itself without its address (p2 = 0): the repeater
        # forwards the beacon to both clients with the sender's address filled in
        server.sendto(raw.header(raw.RSRV_IS_UP, dtype=13, count=5064, p1=42, p2=0), ("127.0.0.1", port))
        want = raw.header(raw.RSRV_IS_UP, dtype=13, count=5064, p1=42, p2=LOOPBACK)
        for s in (a, b):
            got = recv_until(s, lambda p: cmd_of(p) == raw.RSRV_IS_UP)
            assert got == want, got and got.hex()
        # a beacon that names its server is forwarded unchanged
        named = raw.header(raw.RSRV_IS_UP, dtype=13, count=5070, p1=43, p2=0x0A000105)
        server.sendto(named, ("127.0.0.1", port))
        for s in (a, b):
            assert recv_until(s, lambda p: cmd_of(p) == raw.RSRV_IS_UP) == named
        # any datagram goes to every client but its sender
        a.sendto(b"\x00\x05opaque", ("127.0.0.1", port))
        assert recv_until(b, lambda p: p == b"\x00\x05opaque") is not None
        assert recv_until(a, lambda p: p == b"\x00\x05opaque", timeout=0.5) is None, "reflected to the sender"
        assert recv_until(server, lambda p: True, timeout=0.3) is None, "an unregistered sender got data"
        assert repeater.alive()
    finally:
        for s in (a, b, server):
            s.close()
    assert repeater.stop() == 0
    assert "registered" in repeater.stderr()


def test_a_client_that_has_gone_is_dropped(repeater):
    port = repeater.repeater_port
    a, b = udp_socket(), udp_socket()
    gone_port = a.getsockname()[1]
    assert register(a, port) is not None
    a.close()
    assert register(b, port) is not None  # a new client: the repeater checks the others' ports
    err = ""
    deadline = time.monotonic() + DEADLINE
    while time.monotonic() < deadline and f"127.0.0.1:{gone_port} removed" not in err:
        time.sleep(0.05)
        err = repeater.stderr()
    assert f"127.0.0.1:{gone_port} removed" in err, err[-2000:]
    b.close()


def registrations(repeater):
    return repeater.stderr().count(" registered (")


def test_a_second_repeater_exits_quietly(repeater):
    """It asks the port's repeater (REPEATER_REGISTER), is confirmed, and exits 0 without a word:
    exit code 0 with nothing printed is only the answered case (a port held by something that
    does not answer is exit code 1 with a message, below)."""
    env = dict(os.environ, EPICS_CA_REPEATER_PORT=str(repeater.repeater_port))
    n0 = registrations(repeater)
    r = subprocess.run([str(BEAMCTL), "ca-repeater"], env=env, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout, r.stderr) == (0, "", "")
    # the running repeater registered it (its debug log says so)
    assert wait_until(lambda: registrations(repeater) > n0), repeater.stderr()[-2000:]
    assert repeater.alive()
    # `--port` wins over the environment
    r = subprocess.run([str(BEAMCTL), "ca-repeater", "--port", str(repeater.repeater_port)],
                       env=dict(os.environ, EPICS_CA_REPEATER_PORT="1"), capture_output=True, text=True,
                       timeout=20)
    assert (r.returncode, r.stdout, r.stderr) == (0, "", "")


def wait_until(pred, timeout=DEADLINE):
    """Polls pred() (on a repeater's log, say) until true or timeout; returns the last result."""
    deadline = time.monotonic() + timeout
    while not pred() and time.monotonic() < deadline:
        time.sleep(0.05)
    return pred()


def test_a_port_held_by_something_else_is_an_error():
    require_binary()
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("0.0.0.0", 0))
    port = holder.getsockname()[1]
    try:
        r = subprocess.run([str(BEAMCTL), "ca-repeater"], env=dict(os.environ, EPICS_CA_REPEATER_PORT=str(port)),
                           capture_output=True, text=True, timeout=20)
    finally:
        holder.close()
    assert r.returncode == 1
    assert f"UDP port {port} is in use by something that is not a CA repeater" in r.stderr
    r = subprocess.run([str(BEAMCTL), "ca-repeater"], env=dict(os.environ, EPICS_CA_REPEATER_PORT="70000"),
                       capture_output=True, text=True, timeout=20)
    assert r.returncode == 1 and "EPICS_CA_REPEATER_PORT='70000'" in r.stderr


# A libca client: connects to one PV, then waits until libca knows the beacon period of its server
# (ca_beacon_period() stays negative until two beacons from that server reached the client).
# libca registers with the repeater 10 s after it starts (then every second until confirmed), so
# beacons reach it after about 11 s.
CLIENT = r"""
import ctypes, json, sys, time
from epics import ca, dbr
name, wait_s = sys.argv[1], float(sys.argv[2])
chid = ca.create_channel(name, connect=False, auto_cb=False)
ok = ca.connect_channel(chid, timeout=10)
value = ca.get(chid) if ok else None
lib = ca.libca
lib.ca_beacon_period.restype = ctypes.c_double
lib.ca_beacon_period.argtypes = [dbr.chid_t]
period = -1.0
t0 = time.time()
while ok and time.time() - t0 < wait_s:
    ca.poll(0.05)
    period = lib.ca_beacon_period(chid)
    if period > 0:
        break
print(json.dumps({"connected": bool(ok), "value": value, "beacon_period": period}))
"""


def run_libca_client(pv, server_port, repeater_port, path, wait_s):
    env = client_env(server_port)
    env["EPICS_CA_REPEATER_PORT"] = str(repeater_port)
    env["PATH"] = path
    try:
        r = subprocess.run([PYTHON, "-c", CLIENT, pv, str(wait_s)], env=env, capture_output=True, text=True,
                           timeout=wait_s + 60)
    except subprocess.TimeoutExpired as e:
        # the client ends by itself within wait_s (+ its 10 s connect): only a process that kept
        # its pipes open (a caRepeater it spawned, not detached) holds subprocess.run up
        pytest.fail(f"the libca client's pipes were held open past its exit ({e})", pytrace=False)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1]), r.stderr


def beaconing_server(ioc, *repeater_ports):
    """A softioc that sends its beacons (every 0.5 s) to each of the repeater ports on loopback."""
    addrs = " ".join(f"127.0.0.1:{p}" for p in repeater_ports)
    return ioc.start(DB, extra_env={"EPICS_CAS_BEACON_ADDR_LIST": addrs, "EPICS_CAS_BEACON_PERIOD": "0.5"})


def test_libca_client_registers_without_warning_and_gets_beacons(ioc, prefix, repeater, tmp_path):
    lonely_port = free_udp_port()  # no repeater here: the control
    srv = beaconing_server(ioc, repeater.repeater_port, lonely_port)
    empty = tmp_path / "empty-path"  # no caRepeater on PATH: only the running repeater can help
    empty.mkdir()

    res, err = run_libca_client(prefix + "x", srv.port, repeater.repeater_port, str(empty), wait_s=60)
    assert res["connected"] and res["value"] == 4.25, res
    assert "caRepeater" not in err and "repeater" not in err.lower(), err
    assert res["beacon_period"] > 0, f"no beacons reached the client through the repeater: {res}"
    assert res["beacon_period"] < 2.0, res
    assert "registered" in repeater.stderr()

    # the control: the same client where no repeater listens warns and sees no beacons
    res, err = run_libca_client(prefix + "x", srv.port, lonely_port, str(empty), wait_s=3)
    assert res["connected"], res
    assert 'The executable "caRepeater" couldn\'t be located' in err, err
    assert res["beacon_period"] < 0, res


def repeaters_on(port):
    """pids of processes run as `caRepeater` with EPICS_CA_REPEATER_PORT=port."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            argv0 = (d / "cmdline").read_bytes().split(b"\0")[0]
            env = (d / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if os.path.basename(argv0) == b"caRepeater" and f"EPICS_CA_REPEATER_PORT={port}".encode() in env:
            pids.append(int(d.name))
    return pids


def test_libca_spawns_beamctl_as_caRepeater(ioc, prefix, tmp_path):
    """With a `caRepeater` symlink to beamctl on PATH (what build.sh installs in /usr/local/bin),
    libca starts it itself: no warning, the spawned repeater detaches from the client's pipes
    and its terminal, serves the port and forwards beacons."""
    require_binary()
    port = free_udp_port()
    bindir = tmp_path / "bin"
    bindir.mkdir()
    (bindir / "caRepeater").symlink_to(BEAMCTL)
    srv = beaconing_server(ioc, port)
    try:
        # returns once the client exits (else: "pipes held open", see run_libca_client)
        res, err = run_libca_client(prefix + "x", srv.port, port, str(bindir), wait_s=60)
        assert res["connected"] and res["value"] == 4.25, res
        assert "caRepeater" not in err and "repeater" not in err.lower(), err
        assert res["beacon_period"] > 0, f"no beacons through the spawned repeater: {res}"
        pids = repeaters_on(port)
        assert len(pids) == 1, f"expected one spawned caRepeater on port {port}: {pids}"
        pid = pids[0]
        assert os.readlink(f"/proc/{pid}/fd/1") == "/dev/null"
        assert os.readlink(f"/proc/{pid}/fd/2") == "/dev/null"
        assert os.getsid(pid) == pid, "the spawned repeater leads its own session"
        s = udp_socket()
        try:
            assert register(s, port) == raw.header(REPEATER_CONFIRM, p2=LOOPBACK)
        finally:
            s.close()
    finally:
        for pid in repeaters_on(port):
            os.kill(pid, signal.SIGTERM)
        deadline = time.monotonic() + 5
        while repeaters_on(port) and time.monotonic() < deadline:
            time.sleep(0.05)
        for pid in repeaters_on(port):
            os.kill(pid, signal.SIGKILL)


def test_caRepeater_options(tmp_path):
    require_binary()
    link = tmp_path / "caRepeater"
    link.symlink_to(BEAMCTL)
    r = subprocess.run([str(link), "-h"], capture_output=True, text=True, timeout=10)
    assert r.returncode == 0 and "-v" in r.stdout and "EPICS_CA_REPEATER_PORT" in r.stdout
    r = subprocess.run([str(link), "-x"], capture_output=True, text=True, timeout=10)
    assert r.returncode == 1 and "Unknown option 'x'" in r.stderr
    # -v: stays in the foreground with its output, stops on SIGTERM
    port = free_udp_port()
    p = subprocess.Popen([str(link), "-v"], env=dict(os.environ, EPICS_CA_REPEATER_PORT=str(port)),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = p.stdout.readline()
        assert line.strip() == f"ready: CA repeater on udp 0.0.0.0:{port}", line
        p.send_signal(signal.SIGTERM)
        assert p.wait(10) == 0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(10)
