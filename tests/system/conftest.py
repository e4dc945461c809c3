"""System-test infrastructure: start real `beamctl softioc` servers on isolated loopback ports
and talk to them with pyepics (libca), raw sockets, or client subprocesses.

Run with Debian's interpreter (pyepics only imports there):
    /usr/bin/python3 -m pytest tests/system

libca reads EPICS_CA_* when its context is created, so the client environment is fixed here,
before anything imports `epics`.
"""

import contextlib
import ctypes
import os
import shutil
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parents[1]
BEAMCTL = Path(os.environ.get("BEAMCTL_BIN", str(REPO_ROOT / "build" / "release" / "beamctl")))
PYTHON = "/usr/bin/python3"
READY_TIMEOUT = 10.0  # [s]
POOL_SIZE = 8
# Prefixed to the argv of every server IocServer starts (and of other processes a test stops with
# SIGINT, beamctl's Ctrl-C): SIGINT at its default disposition, as from a terminal. A shell that runs
# pytest as a background job (`nohup bash build.sh test &`) sets SIGINT to ignored, and exec passes
# that on to every child. (beamctl blocks SIGINT and reads it from a signalfd, which gets it either
# way; this keeps the tests of it independent of how pytest was started.)
DEFAULT_SIGINT = ["env", "--default-signal=INT"]

if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))


# ---------------------------------------------------------------------------------------------
# Port pool (chosen once per session, before libca starts)
# ---------------------------------------------------------------------------------------------
def _port_is_free(port):
    """True if `port` can be bound on 127.0.0.1 for both TCP and UDP right now."""
    tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        tcp.bind(("127.0.0.1", port))
        udp.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        tcp.close()
        udp.close()


def _pick_ports(n, rng):
    """n distinct free ports below the usual ephemeral range, so client sockets never take them."""
    ports = []
    while len(ports) < n:
        p = rng.randrange(20000, 32000)
        if p in ports or p + 1 in ports or p - 1 in ports:
            continue
        if _port_is_free(p):
            ports.append(p)
    return ports


_rng = random.Random()
SERVER_PORTS = _pick_ports(POOL_SIZE, _rng)
# One extra port nobody listens on: beacon destination and client repeater port.
REPEATER_PORT = _pick_ports(1, random.Random(_rng.random()))[0]
while REPEATER_PORT in SERVER_PORTS:
    REPEATER_PORT = _pick_ports(1, _rng)[0]

CLIENT_ENV = {
    "EPICS_CA_ADDR_LIST": " ".join(f"127.0.0.1:{p}" for p in SERVER_PORTS),
    "EPICS_CA_AUTO_ADDR_LIST": "NO",
    "EPICS_CA_MAX_ARRAY_BYTES": "20000000",
    "EPICS_CA_REPEATER_PORT": str(REPEATER_PORT),
    "EPICS_CA_SERVER_PORT": str(SERVER_PORTS[0]),
}
os.environ.update(CLIENT_ENV)

import epics  # noqa: E402  (must come after the environment is set)
import epics.ca  # noqa: E402
import epics.pv  # noqa: E402

_free_ports = list(SERVER_PORTS)
_free_lock = threading.Lock()


def acquire_port():
    with _free_lock:
        if not _free_ports:
            raise RuntimeError("port pool exhausted: a test started more than %d servers" % POOL_SIZE)
        return _free_ports.pop(0)


def release_port(port):
    with _free_lock:
        if port not in _free_ports:
            _free_ports.append(port)


# ---------------------------------------------------------------------------------------------
# Unique PV prefixes
# ---------------------------------------------------------------------------------------------
_prefix_counter = [0]
_session_tag = "%04x" % random.randrange(0x10000)


def new_prefix():
    """A PV prefix no other test (or earlier run against a stale server) uses."""
    _prefix_counter[0] += 1
    return "BCT%s%03d:" % (_session_tag, _prefix_counter[0])


def forget_pvs(prefix):
    """Drop every pyepics PV/channel whose name starts with prefix, so libca stops searching."""
    for key, pv in list(epics.pv._PVcache_.items()):
        if key[0].startswith(prefix):
            try:
                pv.disconnect()
            except Exception:
                pass
            epics.pv._PVcache_.pop(key, None)
    ctx = epics.ca.current_context()
    cache = epics.ca._cache.get(ctx, {})
    for name in [n for n in list(cache) if n.startswith(prefix)]:
        entry = cache.get(name)
        chid = getattr(entry, "chid", None)
        if chid is not None:
            try:
                epics.ca.clear_channel(chid)
            except Exception:
                pass
        cache.pop(name, None)
    try:
        epics.ca.flush_io()
        epics.ca.poll()
    except Exception:
        pass


# ---------------------------------------------------------------------------------------------
# Server process
# ---------------------------------------------------------------------------------------------
def require_binary():
    if not BEAMCTL.is_file() or not os.access(BEAMCTL, os.X_OK):
        pytest.fail(
            f"beamctl binary not found at {BEAMCTL} (set BEAMCTL_BIN or build the release tree first)",
            pytrace=False,
        )


class IocServer:
    """One `beamctl softioc` process on a pool port. Always stop()/kill() it (fixtures do)."""

    def __init__(self, workdir, db_files, port, macros=None, acf=None, extra_env=None,
                 intf="127.0.0.1", beacon_addr=None, netns=None, name="ioc"):
        self.workdir = Path(workdir)
        self.db_files = [str(f) for f in db_files]
        self.port = port
        self.macros = macros
        self.acf = str(acf) if acf else None
        self.extra_env = dict(extra_env or {})
        self.intf = intf
        self.beacon_addr = beacon_addr or f"127.0.0.1:{REPEATER_PORT}"
        self.netns = netns
        self.name = name
        self.proc = None
        self.ready_line = None
        self.stdout_lines = []
        self.stderr_path = None
        self._ready = threading.Event()
        self._runs = 0

    def argv(self):
        argv = [str(BEAMCTL), "softioc"]
        if self.macros:
            argv += ["-m", self.macros]
        if self.acf:
            argv += ["--acf", self.acf]
        argv += self.db_files
        if self.netns:
            argv = ["ip", "netns", "exec", self.netns] + argv
        return argv

    def env(self):
        env = dict(os.environ)
        env.update({
            "EPICS_CAS_SERVER_PORT": str(self.port),
            "EPICS_CAS_INTF_ADDR_LIST": self.intf or "",
            "EPICS_CAS_BEACON_ADDR_LIST": self.beacon_addr,
            "EPICS_CAS_AUTO_BEACON_ADDR_LIST": "NO",
            "EPICS_CAS_BEACON_PERIOD": "2.0",
        })
        env.update(self.extra_env)
        # a value of None in extra_env (or intf=None) means "leave the variable unset"
        for k in [k for k, v in env.items() if v is None or (k == "EPICS_CAS_INTF_ADDR_LIST" and not v)]:
            del env[k]
        return env

    def start(self, timeout=READY_TIMEOUT):
        require_binary()
        self._runs += 1
        self._ready.clear()
        self.ready_line = None
        self.stdout_lines = []
        self.stderr_path = self.workdir / f"{self.name}.{self._runs}.stderr"
        errf = open(self.stderr_path, "wb")
        self.proc = subprocess.Popen(
            DEFAULT_SIGINT + self.argv(), stdout=subprocess.PIPE, stderr=errf, stdin=subprocess.DEVNULL,
            env=self.env(), cwd=str(self.workdir))
        errf.close()
        threading.Thread(target=self._reader, args=(self.proc,), daemon=True).start()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._ready.wait(0.05):
                return self
            if self.proc.poll() is not None:
                time.sleep(0.1)
                break
        rc = self.proc.poll()
        self.kill()
        pytest.fail(
            f"{self.name}: no 'ready:' line within {timeout:.0f} s (exit code {rc})\n"
            f"argv: {self.argv()}\nstdout: {self.stdout_lines!r}\nstderr: {self.stderr()[-3000:]}",
            pytrace=False)

    def _reader(self, proc):
        for raw in proc.stdout:
            line = raw.decode("utf-8", "replace").rstrip("\n")
            self.stdout_lines.append(line)
            if line.startswith("ready:") and not self._ready.is_set():
                self.ready_line = line
                self._ready.set()

    def stderr(self):
        try:
            return self.stderr_path.read_text(errors="replace")
        except Exception:
            return ""

    def alive(self):
        return self.proc is not None and self.proc.poll() is None

    def signal(self, sig):
        self.proc.send_signal(sig)

    def stop(self, timeout=10.0):
        """SIGTERM and wait; returns the exit code (kills and returns None on timeout)."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
                return None
        return self.proc.returncode

    def kill(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                pass

    def fd_count(self):
        return len(os.listdir(f"/proc/{self.proc.pid}/fd"))

    def rss_kb(self):
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        return 0


class RunServer(IocServer):
    """One `beamctl run ioc.yaml` process on a pool port (same life cycle as IocServer)."""

    def __init__(self, workdir, config, port):
        super().__init__(workdir, [], port, name="run")
        self.config = str(config)

    def argv(self):
        return [str(BEAMCTL), "run", self.config]


class ScannerServer(IocServer):
    """One `beamctl scanner SCANNER.yaml` process (same life cycle as IocServer; no CA port)."""

    def __init__(self, workdir, config):
        super().__init__(workdir, [], 0, name="scanner")
        self.config = str(config)

    def argv(self):
        return [str(BEAMCTL), "scanner", self.config]


class IocFactory:
    def __init__(self, tmp_path, prefix):
        self.tmp_path = Path(tmp_path)
        self.prefix = prefix
        self.servers = []
        self._n = 0

    def write(self, name, text):
        path = self.tmp_path / name
        path.write_text(text)
        return path

    def start(self, db_text=None, db_files=(), macros=None, acf_text=None, acf=None,
              extra_env=None, port=None, start=True):
        """Write db_text (with $(P) = this test's prefix unless macros say otherwise) and start."""
        self._n += 1
        files = list(db_files)
        if db_text is not None:
            files.insert(0, self.write(f"s{self._n}.db", db_text))
        if macros is None:
            macros = f"P={self.prefix}"
        if acf_text is not None:
            acf = self.write(f"s{self._n}.acf", acf_text)
        own_port = port is None
        port = port if port is not None else acquire_port()
        srv = IocServer(self.tmp_path, files, port, macros=macros, acf=acf,
                        extra_env=extra_env, name=f"ioc{self._n}")
        srv.own_port = own_port
        self.servers.append(srv)
        if start:
            srv.start()
        return srv

    def cleanup(self):
        forget_pvs(self.prefix)
        for srv in self.servers:
            srv.kill()
            if getattr(srv, "own_port", False):
                release_port(srv.port)


@pytest.fixture(scope="session", autouse=True)
def ca_repeater():
    """A CA repeater (`beamctl ca-repeater`) on this session's REPEATER_PORT, so that libca (here
    and in client subprocesses) finds one and starts none: a caRepeater that libca starts itself
    (through the /usr/local/bin/caRepeater link build.sh installs) would outlive the session."""
    require_binary()
    proc = subprocess.Popen([str(BEAMCTL), "ca-repeater", "--port", str(REPEATER_PORT)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    line = proc.stdout.readline().decode()
    assert line.startswith("ready:"), f"beamctl ca-repeater on port {REPEATER_PORT}: {line!r}"
    try:
        yield proc
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


@pytest.fixture
def prefix():
    return new_prefix()


@pytest.fixture
def ioc(tmp_path, prefix):
    """Factory: ioc.start(db_text) -> IocServer. Every server is killed at teardown."""
    fac = IocFactory(tmp_path, prefix)
    try:
        yield fac
    finally:
        fac.cleanup()


# ---------------------------------------------------------------------------------------------
# Client helpers
# ---------------------------------------------------------------------------------------------
def wait_for(predicate, timeout=10.0, interval=0.01):
    """Poll predicate (pumping libca) until true or timeout; returns the last result."""
    deadline = time.monotonic() + timeout
    while True:
        res = predicate()
        if res or time.monotonic() > deadline:
            return res
        epics.ca.poll(evt=interval)


def connect(name, timeout=5.0):
    """A connected chid (fails the test if the channel does not connect)."""
    chid = epics.ca.create_channel(name, connect=False, auto_cb=False)
    ok = epics.ca.connect_channel(chid, timeout=timeout)
    assert ok, f"channel {name} did not connect within {timeout} s"
    return chid


ECA_NORMAL, ECA_PUTFAIL = 1, 160


@ctypes.CFUNCTYPE(None, epics.dbr.event_handler_args)
def _put_done(args):
    args.usr.append(args.status)


def put_status(name, value, timeout=5.0):
    """Puts a double (or a string) with a put-callback (ca_array_put_callback of the real libca) and returns the
    status the server's WRITE_NOTIFY reply carried: ECA_NORMAL, or ECA_PUTFAIL for a refused put.
    pyepics' caput(wait=True) cannot tell: it returns 1 once the callback came, whatever its status."""
    chid = connect(name, timeout)
    got = []
    if isinstance(value, str):  # DBR_STRING
        dtype, data = 0, ctypes.create_string_buffer(value.encode(), 40)
    else:  # DBR_DOUBLE
        dtype, data = 6, (ctypes.c_double * 1)(value)
    ret = epics.ca.libca.ca_array_put_callback(dtype, 1, chid, data, _put_done, ctypes.py_object(got))
    assert ret == ECA_NORMAL, f"ca_array_put_callback({name}) returned {ret}"
    epics.ca.flush_io()
    assert wait_for(lambda: got, timeout), f"no put-callback from {name} within {timeout} s"
    return got[0]


def not_connecting(name, timeout=2.0):
    """True if the channel stays unconnected for `timeout` seconds."""
    chid = epics.ca.create_channel(name, connect=False, auto_cb=False)
    ok = epics.ca.connect_channel(chid, timeout=timeout)
    return not ok


def client_env(port):
    """Environment for a client subprocess that sees only the server on `port`."""
    env = dict(os.environ)
    env.update(CLIENT_ENV)
    env["EPICS_CA_ADDR_LIST"] = f"127.0.0.1:{port}"
    return env


def end_process(proc, timeout=10.0):
    """Ends a helper process whatever signal dispositions it inherited: SIGTERM, SIGKILL if it is
    still there after `timeout`, and reaped either way. Returns its exit code."""
    if proc is None:
        return None
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout)
    return proc.returncode


def run_client(code, port, timeout=60, args=()):
    """Run python code in a separate /usr/bin/python3 (own CA context); returns CompletedProcess."""
    return subprocess.run([PYTHON, "-c", code, *args], env=client_env(port), capture_output=True,
                          text=True, timeout=timeout)


class Collector:
    """Thread-safe sink for monitor callbacks."""

    def __init__(self):
        self.lock = threading.Lock()
        self.events = []

    def __call__(self, **kw):
        with self.lock:
            self.events.append(kw)

    def values(self):
        with self.lock:
            return [e["value"] for e in self.events]

    def count(self):
        with self.lock:
            return len(self.events)

    def wait_count(self, n, timeout=10.0):
        return wait_for(lambda: self.count() >= n, timeout)

    def wait_value(self, pred, timeout=10.0):
        def check():
            with self.lock:
                return any(pred(e["value"]) for e in self.events)
        return wait_for(check, timeout)


def subscribe(chid, mask=None, use_time=False, use_ctrl=False, ftype=None, count=0):
    """create_subscription with a Collector; returns (collector, handle). Keep the handle."""
    col = Collector()
    handle = epics.ca.create_subscription(chid, use_time=use_time, use_ctrl=use_ctrl, ftype=ftype,
                                          mask=mask, callback=col, count=count)
    return col, handle


class ModuleServer:
    """One server shared by the tests of a module (each test uses its own records)."""

    def __init__(self, tmp_path_factory, db_text, name="mod", acf_text=None, extra_env=None):
        self.prefix = new_prefix()
        self.fac = IocFactory(tmp_path_factory.mktemp(name), self.prefix)
        self.server = self.fac.start(db_text, acf_text=acf_text, extra_env=extra_env)
        self.port = self.server.port

    def pv(self, suffix):
        return self.prefix + suffix

    def close(self):
        self.fac.cleanup()


def module_server(tmp_path_factory, db_text, **kw):
    """Generator body for module-scoped fixtures: `yield from module_server(...)`."""
    ms = ModuleServer(tmp_path_factory, db_text, **kw)
    try:
        yield ms
    finally:
        ms.close()


@contextlib.contextmanager
def running_ioc(workdir, prefix, ioc_text, files=None, config_name="ioc.yaml"):
    """`beamctl run` on a pool port with `ioc_text` as its configuration (`{name}` and `{prefix}`
    are filled in) and `files` beside it ({file name: text, or a Path to copy}); yields the server
    once m0-Stat-OK is 1, then stops it and forgets the prefix's PVs."""
    workdir = Path(workdir)
    for name, content in (files or {}).items():
        if isinstance(content, Path):
            shutil.copy(content, workdir / name)
        else:
            (workdir / name).write_text(content)
    cfg = workdir / config_name
    cfg.write_text(ioc_text.format(name=prefix.rstrip(":"), prefix=prefix))
    port = acquire_port()
    srv = RunServer(workdir, cfg, port)
    try:
        srv.start()  # inside: a server that does not start still gives its port back
        assert wait_for(lambda: epics.ca.get(connect(prefix + "m0-Stat-OK")) == 1)
        yield srv
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


@pytest.fixture
def demo(tmp_path):
    """The demo beamline (examples/demo/ioc.yaml) on a pool port, once its bus is OK."""
    port = acquire_port()
    srv = RunServer(tmp_path, REPO_ROOT / "examples" / "demo" / "ioc.yaml", port)
    try:
        srv.start()
        assert wait_for(lambda: epics.ca.get(connect("DEMO:m0-Stat-OK")) == 1, timeout=10)
        yield srv
    finally:
        srv.stop()
        srv.kill()
        forget_pvs("DEMO:")
        release_port(port)


# ---------------------------------------------------------------------------------------------
# Network namespaces (tests across simulated hosts and raw links over veth pairs)
# ---------------------------------------------------------------------------------------------
def probe_netns():
    """None if network namespaces joined by veth pairs can be made here, else why not. Really
    does it: adds a namespace, runs a command in it (`ip netns exec` needs "/" to be a mount
    point, which it is not in a plain chroot), moves one end of a veth pair into it, and removes
    everything again."""
    if shutil.which("ip") is None:
        return "the 'ip' command is not installed (Debian package iproute2)"
    tag = "%06x" % random.randrange(1 << 24)
    ns, veth = f"bcprobe{tag}", f"bcprobe{tag}"

    def ip(*args):
        return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20)

    def failed(what, r):
        return f"{what}: " + (r.stderr.strip() or f"exit code {r.returncode}")

    made_ns = made_link = False
    try:
        r = ip("netns", "add", ns)
        if r.returncode != 0:
            return failed("ip netns add", r)
        made_ns = True
        r = ip("netns", "exec", ns, "ip", "link", "set", "lo", "up")
        if r.returncode != 0:
            return failed("ip netns exec", r)
        r = ip("link", "add", veth, "type", "veth", "peer", "name", "eth0", "netns", ns)
        if r.returncode != 0:
            return failed("ip link add type veth", r)
        made_link = True
        return None
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"cannot run ip: {e}"
    finally:
        try:
            if made_link:
                ip("link", "del", veth)
            if made_ns:
                ip("netns", "del", ns)
        except (OSError, subprocess.TimeoutExpired):
            pass


@pytest.fixture(scope="session")
def netns_unavailable():
    """Why network namespaces with veth pairs cannot be made here (None if they can); probed once."""
    return probe_netns()


@pytest.fixture
def require_netns(netns_unavailable):
    """Skips the test, saying why, where network namespaces and veth pairs cannot be made (a chroot
    whose "/" is not a mount point, no CAP_SYS_ADMIN/CAP_NET_ADMIN, no iproute2)."""
    if netns_unavailable:
        pytest.skip(f"network namespaces cannot be made here ({netns_unavailable}); "
                    "this test needs root or CAP_SYS_ADMIN + CAP_NET_ADMIN, outside a plain chroot")


@contextlib.contextmanager
def running_config(tmp_path, prefix, text, ready, timeout=10.0):
    """`beamctl run` on the IOC file `text` (written to tmp_path/ioc.yaml) on a free port, yielded
    once `ready()` holds; stopped, its PVs under `prefix` forgotten and its port released after."""
    require_binary()
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(text)
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    try:
        srv.start()
        assert wait_for(ready, timeout)
        yield srv
        assert srv.alive()
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)
