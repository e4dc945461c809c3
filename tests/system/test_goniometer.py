"""smartControl through its line protocol (examples/goniometer, docs/goniometer.md): a client on
TCP and one on the pseudo-terminal drive the goniometer's motors, shutter and scaler; pyepics sees
the motors move, the shutter open for a scan's exposure, and the setup table as PVs."""

import os
import random
import select
import socket
import time
from pathlib import Path

import epics
from epics import ca

from conftest import _pick_ports, connect, put_status, running_config, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def get(name, **kw):
    return ca.get(connect(name), **kw)


def running_goniometer(tmp_path, prefix, port):
    cfg = (EXAMPLES / "goniometer" / "ioc.yaml").read_text()
    d = EXAMPLES / "goniometer"
    cfg = cfg.replace("ioc: {name: GON}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    cfg = cfg.replace("plant: plant.yaml", f"plant: {d / 'plant.yaml'}").replace("file: rotary.yaml", f"file: {d / 'rotary.yaml'}")
    cfg = cfg.replace("file: goniometer.db, macros: {P: \"GON:\"}", f"file: {d / 'goniometer.db'}, macros: {{P: \"{prefix}\"}}")
    cfg = cfg.replace('"GON:', f'"{prefix}')
    cfg = cfg.replace("port: 17010", f"port: {port}").replace("pty: /tmp/beamctl-smart", f"pty: {tmp_path / 'smart.pty'}")
    assert "GON" not in cfg.split("smart_control:")[1], cfg

    def ready():
        if get(prefix + "smart:OmegaExists") != 1:
            return False
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return True
        except OSError:
            return False

    return running_config(tmp_path, prefix, cfg, ready, timeout=20)


class Client:
    """One line protocol connection: send a line, read the reply (lines end with CR LF)."""

    def __init__(self, port):
        self.s = socket.create_connection(("127.0.0.1", port), timeout=60)
        self.buf = b""

    def read(self, timeout=60):
        deadline = time.monotonic() + timeout
        while b"\r\n" not in self.buf:
            self.s.settimeout(max(0.01, deadline - time.monotonic()))
            chunk = self.s.recv(4096)
            assert chunk, "the server closed the connection"
            self.buf += chunk
        line, self.buf = self.buf.split(b"\r\n", 1)
        return line.decode()

    def ask(self, line, timeout=60):
        self.s.sendall(line.encode() + b"\n")
        return self.read(timeout)

    def close(self):
        self.s.close()


def value(reply, name):
    return float(reply.split(name + "=")[1].split()[0])


def test_moves_a_scan_and_counting_over_tcp(tmp_path, prefix):
    p = prefix
    port = _pick_ports(1, random.Random())[0]
    with running_goniometer(tmp_path, p, port):
        c = Client(port)
        assert c.ask("ID") == "ID OK beamctl smartControl OMEGA PHI"
        # omega 140 goes to the motor's -220 (the cut window -230 .. 130); phi counts the other way from 90
        r = c.ask("MOVE OMEGA 140 PHI 30")
        assert r.startswith("MOVE OK"), r
        assert abs(value(r, "OMEGA") - 140) < 0.02 and abs(value(r, "PHI") - 30) < 0.02
        assert abs(get(p + "Omega.RBV") + 220) < 0.02
        assert abs(get(p + "Phi.RBV") - 60) < 0.02
        assert wait_for(lambda: abs(get(p + "smart:OmegaPosition") - 140) < 0.02, 5)
        # a scan: the shutter opens at the start, closes at the end; the trigger with it
        seen = []
        shutter = epics.PV(p + "Shutter", auto_monitor=True, callback=lambda value=None, **kw: seen.append(value))
        shutter.wait_for_connection(5)
        r = c.ask("SCAN OMEGA 10 12 0.5")
        assert r.startswith("SCAN OK"), r
        assert abs(value(r, "OMEGA") - 12) < 0.02
        assert value(r, "SECONDS") >= 0.5
        rate = get(p + "IonChamber")
        assert abs(value(r, "COUNTS") - rate * value(r, "SECONDS")) < 0.2 * rate * value(r, "SECONDS")
        assert wait_for(lambda: seen[-1:] == [0] and 1 in seen, 5), seen
        assert get(p + "DetTrigger") == 0
        assert get(p + "Omega.VELO") == 20  # given back after the exposure
        # counting alone
        r = c.ask("COUNT 0.3")
        assert r.startswith("COUNT OK"), r
        assert abs(float(r.split()[2]) - rate * 0.3) < 0.1 * rate * 0.3
        # refused before anything moves: beyond the soft limits (no cut window on phi)
        r = c.ask("MOVE PHI -400")
        assert r.startswith("MOVE ERR PHI: 490.000 (motor) is beyond the motor's soft limits"), r
        assert abs(get(p + "Phi.RBV") - 60) < 0.02
        # STOP from a second client ends a move: ERR, never OK
        c.s.sendall(b"MOVE OMEGA -100\n")
        time.sleep(0.5)
        other = Client(port)
        assert other.ask("STOP") == "STOP OK"
        r = c.read()
        assert r.startswith("MOVE ERR OMEGA ended short at"), r
        assert "(target -100.000)" in r
        assert get(p + "smart:Clients") == 2
        other.close()
        c.close()
        assert wait_for(lambda: get(p + "smart:Clients") == 0, 5)


def test_the_pty_and_the_setup_table(tmp_path, prefix):
    p = prefix
    port = _pick_ports(1, random.Random())[0]
    with running_goniometer(tmp_path, p, port):
        pty = tmp_path / "smart.pty"
        assert pty.is_symlink() and os.readlink(pty).startswith("/dev/pts/")
        fd = os.open(pty, os.O_RDWR | os.O_NOCTTY)
        try:
            def ask(line):
                os.write(fd, line.encode() + b"\r")  # a serial client's CR
                buf = b""
                while b"\r\n" not in buf:
                    assert select.select([fd], [], [], 30)[0], "no reply on the pty"
                    buf += os.read(fd, 4096)
                return buf.split(b"\r\n")[0].decode()

            assert ask("POS") == "POS OK OMEGA=0.000 PHI=90.000"
            # the setup table through its PVs: phi's zero moves to the motor's 100
            assert put_status(p + "smart:PhiOffset", 100) == 1
            assert ask("POS PHI") == "POS OK PHI=100.000"
            assert put_status(p + "smart:PhiSign", 0) == 1  # Positive
            assert ask("POS PHI") == "POS OK PHI=-100.000"
            assert ask("SHUTTER OPEN") == "SHUTTER OK OPEN"
            assert wait_for(lambda: get(p + "Shutter") == 1 and get(p + "smart:Shutter") == 1, 5)
            assert ask("SHUTTER CLOSE") == "SHUTTER OK CLOSED"
        finally:
            os.close(fd)


def test_bad_lines_are_answered_and_counted(tmp_path, prefix):
    p = prefix
    port = _pick_ports(1, random.Random())[0]
    with running_goniometer(tmp_path, p, port):
        c = Client(port)
        assert c.ask("FLY AWAY").startswith("FLY ERR unknown command 'FLY'")
        assert c.ask("MOVE OMEGA 1e999") == "MOVE ERR '1e999' is not a number (position)"
        assert c.ask("X" * 1000) == "ERR line too long (at most 256 bytes)"
        c.s.sendall(bytes(range(14, 256)) + b"\n")  # binary garbage: answered, nothing else
        assert c.read() == "ERR byte 0x0e at column 1 is not printable ASCII"
        assert c.ask("ID").startswith("ID OK")  # the connection is still good
        assert wait_for(lambda: get(p + "smart:Errors") == 4, 5)
        assert get(p + "Omega.RBV") == 0 and get(p + "Shutter") == 0
        c.close()
