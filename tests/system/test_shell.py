"""`beamctl shell`: iocsh introspection of a running IOC through its local UNIX socket (dbl, dbpr,
dbgf, dbpf, dbtr, scanppl, casr, help), against `beamctl softioc` and `beamctl run`; the socket is
the IOC's (0600, removed at exit); malformed input gets an error and never stops the IOC. Also
autosave in `beamctl run` (ioc.yaml `autosave:`)."""

import os
import shutil
import socket
import stat
import subprocess
import tempfile
import time

import pytest

from conftest import (BEAMCTL, IocServer, acquire_port, connect, forget_pvs, release_port,
                      running_ioc, wait_for)

import epics

DB = """record(ao, "$(P)ao") {
    field(DESC, "set point")
    field(PREC, "2")
    field(EGU, "mm")
}
record(calc, "$(P)calc") {
    field(INPA, "$(P)ao")
    field(CALC, "A*2")
}
record(ai, "$(P)slow") { field(SCAN, "1 second") }
record(ai, "$(P)fast") { field(SCAN, ".1 second") field(PHAS, "1") }
record(waveform, "$(P)wf") { field(FTVL, "DOUBLE") field(NELM, "4") }
"""


class SoftIoc(IocServer):
    def __init__(self, workdir, args, port, extra_env=None):
        super().__init__(workdir, [], port, name="sh", extra_env=extra_env)
        self.args = [str(a) for a in args]

    def argv(self):
        return [str(BEAMCTL), "softioc", *self.args]


def socket_of(srv):
    lines = [l for l in srv.stdout_lines if l.startswith("shell: ")]
    assert lines, f"no 'shell:' line: {srv.stdout_lines}"
    return lines[0][len("shell: "):]


def shell(sock, *commands, stdin=None):
    """Runs `beamctl shell --socket SOCK -c ...`; returns (exit code, stdout, stderr)."""
    args = [str(BEAMCTL), "shell", "--socket", sock]
    for c in commands:
        args += ["-c", c]
    r = subprocess.run(args, input=stdin, capture_output=True, text=True, timeout=60)
    return r.returncode, r.stdout, r.stderr


@pytest.fixture
def softioc(tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    port = acquire_port()
    srv = SoftIoc(tmp_path, ["-m", f"P={prefix}", "x.db"], port).start()
    try:
        yield srv
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


def test_socket_is_the_iocs_own_and_goes_with_it(softioc, prefix):
    sock = socket_of(softioc)
    st = os.stat(sock)
    assert stat.S_ISSOCK(st.st_mode)
    assert stat.S_IMODE(st.st_mode) == 0o660  # this user and the socket group (its own by default)
    assert st.st_gid == os.getegid()
    assert os.stat(os.path.dirname(sock)).st_uid == os.getuid()
    assert stat.S_IMODE(os.stat(os.path.dirname(sock)).st_mode) == 0o700  # nobody else gets to the file
    assert softioc.stop() == 0
    assert not os.path.exists(sock)


def test_dbl_dbgf_dbpf_dbpr(softioc, prefix):
    sock = socket_of(softioc)
    rc, out, _ = shell(sock, "dbl")
    assert rc == 0
    assert out.split() == [prefix + n for n in ("slow", "fast", "ao", "calc", "wf")]  # by type, then load order
    rc, out, _ = shell(sock, 'dbl ao "DESC EGU"', f"dbl {prefix}*a*")
    assert out.splitlines() == [f'{prefix}ao, "set point", "mm"', prefix + "fast", prefix + "ao",
                                prefix + "calc"]

    rc, out, _ = shell(sock, f"dbpf {prefix}ao 2.5", f"dbgf {prefix}ao", f'dbpf {prefix}wf "[1, 2, 3]"')
    assert rc == 0
    assert out.splitlines()[:2] == ["DBF_DOUBLE:         2.5       "] * 2
    assert out.splitlines()[2].startswith("DBF_DOUBLE[3]:      1         2         3")
    assert epics.caget(prefix + "ao", timeout=5) == 2.5  # the same database the CA clients see

    rc, out, _ = shell(sock, f"dbpr {prefix}ao")
    assert rc == 0
    assert "DESC: set point" in out and f"NAME: {prefix}ao" in out and "VAL: 2.50" in out
    assert "EGU:" not in out  # level 0: the main fields only
    rc, out, _ = shell(sock, f"dbpr {prefix}ao 1")
    assert "EGU: mm" in out and "PREC: 2" in out


def test_refused_puts_and_errors_say_why(softioc, prefix):
    sock = socket_of(softioc)
    rc, out, _ = shell(sock, f"dbpf {prefix}ao.STAT 1")
    assert rc == 1 and "read-only" in out, out
    rc, out, _ = shell(sock, f"dbpf {prefix}ao notanumber")
    assert rc == 1 and "cannot be converted" in out, out
    rc, out, _ = shell(sock, "dbgf nosuch:rec")
    assert rc == 1 and "PV 'nosuch:rec' not found" in out
    rc, out, _ = shell(sock, "frobnicate")
    assert rc == 1 and "unknown command 'frobnicate'" in out
    rc, out, _ = shell(sock, "help")
    assert rc == 0 and "dbtr NAME" in out and "casr" in out


def test_dbtr_processes_the_record(softioc, prefix):
    sock = socket_of(softioc)
    epics.caput(prefix + "ao", 4, wait=True, timeout=5)
    assert epics.caget(prefix + "calc", timeout=5) == 0  # Passive, nothing processed it
    rc, out, _ = shell(sock, f"dbtr {prefix}calc")
    assert rc == 0
    assert "VAL: 8" in out, out
    assert epics.caget(prefix + "calc", timeout=5) == 8


def test_scanppl(softioc, prefix):
    sock = socket_of(softioc)
    rc, out, _ = shell(sock, "scanppl")
    lines = out.splitlines()
    assert lines[lines.index("Scan list for 1 second:") + 1] == "    " + prefix + "slow"
    assert lines[lines.index("Scan list for .1 second:") + 1] == "    " + prefix + "fast"
    rc, out, _ = shell(sock, "scanppl .1")
    assert out.splitlines() == ["Scan list for .1 second:", "    " + prefix + "fast"]


def test_casr_counts_clients_and_channels(softioc, prefix):
    sock = socket_of(softioc)
    rc, out, _ = shell(sock, "casr")
    assert rc == 0 and out.startswith("Channel Access Server V4.13\n")
    epics.caget(prefix + "ao", timeout=5)
    epics.caget(prefix + "calc", timeout=5)
    rc, out, _ = shell(sock, "casr 2")
    assert "Connected circuits:" in out, out
    assert "2 Channels" in out, out
    assert "subscription(s)" in out and "Circuits opened" in out
    assert f"\t{prefix}calc\n" in out, out  # level 1 and up: the channel names


def test_stdin_lines_and_malformed_input(softioc, prefix):
    sock = socket_of(softioc)
    rc, out, _ = shell(sock, stdin=f"# a comment\n\ndbgf {prefix}ao.EGU\ndbl ao\n")
    assert rc == 0
    assert out.splitlines() == ['DBF_STRING:         "mm"      ', prefix + "ao"]
    rc, out, _ = shell(sock, 'dbgf "unbalanced')
    assert rc == 1 and "Unbalanced quote" in out

    # A huge line without a newline: an error and the connection closes; junk bytes: errors.
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(sock)
    s.settimeout(20)
    try:
        s.sendall(b"x" * (300 * 1024))
    except (BrokenPipeError, ConnectionResetError):
        pass
    got = b""
    while True:
        try:
            chunk = s.recv(4096)
        except ConnectionResetError:
            break
        if not chunk:
            break
        got += chunk
    s.close()
    assert b"line longer than 65536 bytes" in got, got
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(sock)
    s.settimeout(20)
    s.sendall(b"\x00\xff\xfe garbage\n")
    reply = b""
    while not reply.endswith((b"\x001", b"\x000")):
        reply += s.recv(4096)
    assert reply.endswith(b"\x001") and b"error" in reply, reply
    s.close()
    # The IOC serves on.
    assert softioc.alive()
    assert epics.caget(prefix + "ao.EGU", timeout=5) == "mm"
    rc, out, _ = shell(sock, f"dbgf {prefix}ao.EGU")
    assert rc == 0


def test_cannot_connect_is_a_clear_error(tmp_path):
    rc, out, err = shell(str(tmp_path / "nothing.sock"), "dbl")
    assert rc == 2 and "cannot connect" in err


RUN_IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 500}}
buses:
  - id: 0
    link: {{type: sim}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
db:
  - {{file: extra.db, macros: {{P: "{prefix}"}}}}
autosave: {{dir: autosave, period_s: 1}}
"""

EXTRA_DB = """record(ao, "$(P)gain") {
    field(PREC, "1")
    field(PINI, "YES")
    field(OUT, "$(P)copy PP")
    info(autosaveFields, "VAL DESC")
}
record(ao, "$(P)copy") { }
"""


def test_beamctl_run_shell_and_autosave(tmp_path, prefix):
    with running_ioc(tmp_path, prefix, RUN_IOC, files={"extra.db": EXTRA_DB}) as srv:
        sock = socket_of(srv)
        assert os.path.basename(sock) == prefix.rstrip(":") + ".sock"
        by_name = subprocess.run([str(BEAMCTL), "shell", prefix.rstrip(":"), "-c", f"dbl {prefix}m0-Stat-OK"],
                                 capture_output=True, text=True, timeout=60)
        assert by_name.stdout == prefix + "m0-Stat-OK\n", by_name  # NAME: the default socket of that IOC
        rc, out, _ = shell(sock, f"dbl {prefix}m0-Stat*", f"dbgf {prefix}m0-Stat-OK")
        assert rc == 0
        assert prefix + "m0-Stat-OK" in out.splitlines()
        assert out.splitlines()[-1].rstrip() == 'DBF_STRING:         "OK"'  # a bi: its state string
        rc, out, _ = shell(sock, f"dbpf {prefix}gain 3.5", f"dbpr {prefix}gain", "casr", "scanppl")
        assert rc == 0, out
        assert "VAL: 3.5" in out and "Channel Access Server" in out
        assert epics.caget(prefix + "copy", timeout=5) == 3.5
        epics.caput(prefix + "gain.DESC", "saved", wait=True, timeout=5)
        sav = tmp_path / "autosave" / "info_settings.sav"
        assert wait_for(lambda: sav.exists() and f"{prefix}gain.DESC saved\n" in sav.read_text(),
                        timeout=30), sav.read_text() if sav.exists() else "(no file)"
        assert f"{prefix}gain.VAL 3.5\n" in sav.read_text()
    assert not os.path.exists(sock)

    with running_ioc(tmp_path, prefix, RUN_IOC, files={"extra.db": EXTRA_DB}) as srv:
        # gain.VAL and .DESC, and the devIocStats records' own tags: $(IOC):ACCESS (settings) and
        # START_CNT (positions, pass 0), which counts this second start
        assert "restored 3 value(s)" in srv.stderr() and "info_settings.sav" in srv.stderr(), srv.stderr()
        assert "restored 1 value(s)" in srv.stderr() and "info_positions.sav" in srv.stderr(), srv.stderr()
        assert epics.caget(prefix + "START_CNT", timeout=10) == 2
        assert epics.caget(prefix + "gain", timeout=10) == 3.5
        assert epics.caget(prefix + "gain.DESC", timeout=5) == "saved"
        assert epics.caget(prefix + "copy", timeout=5) == 3.5  # PINI after the restore


CONNECT_AS_OTHER = r"""
import socket, sys
s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
s.connect(sys.argv[1])
try:
    s.sendall(b"dbl\n")
except (BrokenPipeError, ConnectionResetError):
    pass  # a refusing server may have answered and closed already: read what it said
data = b""
while True:
    try:
        chunk = s.recv(65536)
    except ConnectionResetError:
        break
    if not chunk:
        break
    data += chunk
    if b"\0" in data and len(data) >= data.index(b"\0") + 2:
        break
print(data.decode(errors="replace"))
"""


def test_a_connection_from_another_user_is_refused(tmp_path, prefix):
    """Issue 19: the shell socket checks who connected (SO_PEERCRED), not only its file mode: with
    the socket opened up to everybody (mode 0666 in a world-traversable directory), another uid
    gets an error and the IOC logs the refusal; the IOC's own user still gets answers."""
    if os.getuid() != 0:
        pytest.skip("needs root to run a client as another uid (nobody)")
    (tmp_path / "x.db").write_text(DB)
    open_dir = tempfile.mkdtemp(prefix="beamctl-shell-")  # pytest's own tree is 0700
    os.chmod(open_dir, 0o777)
    sock = os.path.join(open_dir, "ioc.sock")
    port = acquire_port()
    srv = SoftIoc(tmp_path, ["--shell-socket", sock, "-m", f"P={prefix}", "x.db"], port).start()
    try:
        assert socket_of(srv) == sock
        os.chmod(sock, 0o666)  # a mode changed by mistake: the credentials check still holds

        def as_nobody():
            os.setgid(65534)
            os.setuid(65534)

        r = subprocess.run(["/usr/bin/python3", "-c", CONNECT_AS_OTHER, sock], capture_output=True, text=True,
                           timeout=30, preexec_fn=as_nobody, cwd="/")
        assert r.returncode == 0, r.stderr
        assert "error: uid 65534 may not use this IOC's shell" in r.stdout, r.stdout
        assert f"{prefix}ao" not in r.stdout
        assert wait_for(lambda: "refused a connection from uid 65534" in srv.stderr(), timeout=5), srv.stderr()[-2000:]
        rc, out, _ = shell(sock, "dbl")  # root (this test's user) is served
        assert rc == 0 and f"{prefix}ao" in out
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)
        shutil.rmtree(open_dir, ignore_errors=True)


def test_members_of_the_socket_group_are_served(tmp_path, prefix):
    """Issue 19: BEAMCTL_SOCKET_GROUP names the group that may use the IOC's local sockets: the
    socket file is 0660 and belongs to it; a process of another user that has the group among its
    groups is served, one without it is refused."""
    if os.getuid() != 0:
        pytest.skip("needs root to run clients as another uid (nobody)")
    (tmp_path / "x.db").write_text(DB)
    open_dir = tempfile.mkdtemp(prefix="beamctl-shell-")
    os.chmod(open_dir, 0o755)
    sock = os.path.join(open_dir, "ioc.sock")
    port = acquire_port()
    srv = SoftIoc(tmp_path, ["--shell-socket", sock, "-m", f"P={prefix}", "x.db"], port,
                  extra_env={"BEAMCTL_SOCKET_GROUP": "users"}).start()
    try:
        st = os.stat(sock)
        assert stat.S_IMODE(st.st_mode) == 0o660 and st.st_gid == 100  # Debian's "users"

        def nobody(groups):
            def run():
                os.setgroups(groups)
                os.setgid(65534)
                os.setuid(65534)
            return run

        member = subprocess.run(["/usr/bin/python3", "-c", CONNECT_AS_OTHER, sock], capture_output=True, text=True,
                                timeout=30, preexec_fn=nobody([100]), cwd="/")
        assert member.returncode == 0, member.stderr
        assert "may not use" not in member.stdout and f"{prefix}ao" in member.stdout, member.stdout
        other = subprocess.run(["/usr/bin/python3", "-c", CONNECT_AS_OTHER, sock], capture_output=True, text=True,
                               timeout=30, preexec_fn=nobody([]), cwd="/")
        assert "PermissionError" in other.stderr, other.stdout + other.stderr  # the file's mode keeps it out
        os.chmod(sock, 0o666)  # and were the mode opened by mistake, the credentials check holds
        other = subprocess.run(["/usr/bin/python3", "-c", CONNECT_AS_OTHER, sock], capture_output=True, text=True,
                               timeout=30, preexec_fn=nobody([]), cwd="/")
        assert "error: uid 65534 may not use this IOC's shell" in other.stdout, other.stdout + other.stderr
        assert wait_for(lambda: "root and group users may use it" in srv.stderr(), timeout=5), srv.stderr()[-2000:]
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)
        shutil.rmtree(open_dir, ignore_errors=True)
