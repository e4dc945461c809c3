"""Access security: ACF groups, user/host rules, denied reads and writes on the wire, live
reload on SIGHUP with new ACCESS_RIGHTS to connected clients (ca-protocol.md §3)."""

import os
import signal
import subprocess

import pytest

import ca_raw as raw
from conftest import BEAMCTL, acquire_port, connect, release_port, require_binary, wait_for

import epics
from epics import ca

ACF = """
UAG(admins) { tester, alice }
HAG(goodhosts) { trusted }
ASG(DEFAULT) {
    RULE(1, READ)
    RULE(1, WRITE)
}
ASG(RO) {
    RULE(1, READ)
}
ASG(NONE)
ASG(ADMIN) {
    RULE(1, READ)
    RULE(1, WRITE) { UAG(admins) }
}
ASG(HOSTS) {
    RULE(1, READ)
    RULE(1, WRITE) { HAG(goodhosts) }
}
"""

DB = """
record(ao, "$(P)rw") { field(VAL, "1") field(PINI, "YES") }
record(ao, "$(P)ro") { field(ASG, "RO") field(VAL, "2") field(PINI, "YES") }
record(ao, "$(P)none") { field(ASG, "NONE") field(VAL, "3") field(PINI, "YES") }
record(ao, "$(P)admin") { field(ASG, "ADMIN") }
record(ao, "$(P)hosts") { field(ASG, "HOSTS") }
record(ao, "$(P)swap") { field(VAL, "4") field(PINI, "YES") }
"""


@pytest.fixture
def srv(ioc):
    s = ioc.start(DB, acf_text=ACF)
    s.prefix = ioc.prefix
    s.pv = lambda suffix: ioc.prefix + suffix
    return s


def test_pyepics_sees_rights(srv):
    rw, ro, none = (connect(srv.pv(n)) for n in ("rw", "ro", "none"))
    assert (ca.read_access(rw), ca.write_access(rw)) == (True, True)
    assert (ca.read_access(ro), ca.write_access(ro)) == (True, False)
    assert (ca.read_access(none), ca.write_access(none)) == (False, False)
    assert ca.get(ro) == 2.0
    with pytest.raises(ca.CASeverityException):
        ca.put(ro, 5.0)
    assert ca.get(ro) == 2.0
    assert ca.put(rw, 5.0, wait=True) == 1 and ca.get(rw) == 5.0
    # fields share the record's group
    ro_egu = connect(srv.pv("ro.EGU"))
    assert (ca.read_access(ro_egu), ca.write_access(ro_egu)) == (True, False)


def test_denials_on_the_wire(srv):
    with raw.Circuit("127.0.0.1", srv.port, user="nobody") as c:
        ro = c.create(srv.pv("ro"))
        none = c.create(srv.pv("none"))
        assert (ro["access"], none["access"]) == (1, 0)
        # WRITE without access: ERROR ECA_NOWTACCESS carrying our header; circuit stays open
        req = raw.message(raw.WRITE, raw.encode_values(raw.DOUBLE, [9.0]), dtype=raw.DOUBLE,
                          count=1, p1=ro["sid"], p2=ro["cid"])
        c.send(req)
        m = c.recv_cmd(raw.ERROR)
        assert (m.p1, m.p2) == (ro["cid"], raw.ECA_NOWTACCESS)
        assert m.payload[:16] == req[:16], "ERROR embeds the failing request header (§3)"
        # WRITE_NOTIFY without access is answered with the status
        assert c.write_notify(ro, [9.0], dtype=raw.DOUBLE).p1 == raw.ECA_NOWTACCESS
        assert c.read(ro)[1]["value"] == [2.0]
        # READ_NOTIFY without read access: reply with ECA_NORDACCESS and a zeroed payload
        m, d = c.read(none, dtype=raw.TIME_DOUBLE)
        assert m.p1 == raw.ECA_NORDACCESS
        assert m.payload == b"\0" * len(m.payload) and len(m.payload) == 24
        # monitors too
        sub = c.subscribe(none, dtype=raw.DOUBLE)
        m = c.recv_cmd(raw.EVENT_ADD)
        assert (m.p1, m.p2) == (raw.ECA_NORDACCESS, sub)
        assert m.payload == b"\0" * 8
        assert c.echo().cmd == raw.ECHO


@pytest.mark.parametrize("user,host,admin_rights,hosts_rights", [
    ("tester", "somewhere", 3, 1),
    ("alice", "trusted", 3, 3),
    ("bob", "trusted", 1, 3),
    ("bob", "somewhere", 1, 1),
])
def test_user_and_host_rules(srv, user, host, admin_rights, hosts_rights):
    with raw.Circuit("127.0.0.1", srv.port, user=user, hostname=host) as c:
        assert c.create(srv.pv("admin"))["access"] == admin_rights
        assert c.create(srv.pv("hosts"))["access"] == hosts_rights
        assert c.create(srv.pv("rw"))["access"] == 3


def test_sighup_reload_changes_rights_live(srv, tmp_path):
    acf_path = srv.acf
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("swap"))
        assert ch["access"] == 3
        pv = epics.PV(srv.pv("swap"), auto_monitor=False)
        assert pv.wait_for_connection(5) and ca.write_access(pv.chid)
        # make DEFAULT read-only and reload
        with open(acf_path, "w") as f:
            f.write(ACF.replace("ASG(DEFAULT) {\n    RULE(1, READ)\n    RULE(1, WRITE)\n}",
                                "ASG(DEFAULT) {\n    RULE(1, READ)\n}"))
        srv.signal(signal.SIGHUP)
        m = c.recv_cmd(raw.ACCESS_RIGHTS, timeout=10, skip=())
        assert (m.p1, m.p2) == (ch["cid"], 1), "connected clients get the new ACCESS_RIGHTS"
        assert wait_for(lambda: not ca.write_access(pv.chid), timeout=10), "pyepics not told of new rights"
        with pytest.raises(ca.CASeverityException):
            pv.put(8.0)
        # the raw WRITE is now refused by the server itself
        c.write(ch, [8.0], dtype=raw.DOUBLE)
        assert c.recv_cmd(raw.ERROR).p2 == raw.ECA_NOWTACCESS
        assert c.read(ch)[1]["value"] == [4.0]
        # restore and reload again
        with open(acf_path, "w") as f:
            f.write(ACF)
        srv.signal(signal.SIGHUP)
        m = c.recv_cmd(raw.ACCESS_RIGHTS, timeout=10, skip=())
        assert (m.p1, m.p2) == (ch["cid"], 3)
        assert wait_for(lambda: ca.write_access(pv.chid), timeout=10)
        assert pv.put(8.0, wait=True) == 1
        assert c.read(ch)[1]["value"] == [8.0]
    assert srv.alive(), "SIGHUP must not stop the server"


def test_changing_asg_field_changes_rights(srv):
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(srv.pv("swap"))
        asg = c.create(srv.pv("swap.ASG"))
        assert ch["access"] == 3
        c.send(raw.message(raw.WRITE_NOTIFY, raw.encode_values(raw.STRING, ["RO"]),
                           dtype=raw.STRING, count=1, p1=asg["sid"], p2=777))
        seen, status = {}, None
        while len(seen) < 2 or status is None:
            m = c.recv(timeout=5)
            if m.cmd == raw.ACCESS_RIGHTS:
                seen[m.p1] = m.p2
            elif m.cmd == raw.WRITE_NOTIFY and m.p2 == 777:
                status = m.p1
            else:
                raise AssertionError(f"unexpected {m}")
        assert status == raw.ECA_NORMAL
        assert seen == {ch["cid"]: 1, asg["cid"]: 1}, "every channel of the record is told"
        c.write(ch, [1.0], dtype=raw.DOUBLE)
        assert c.recv_cmd(raw.ERROR).p2 == raw.ECA_NOWTACCESS


def test_bad_acf_is_a_load_error(ioc):
    require_binary()
    bad = ioc.write("bad.acf", "ASG(DEFAULT) { RULE(1, READ }\n")
    db = ioc.write("x.db", 'record(ai, "$(P)x") { }\n')
    port = acquire_port()
    try:
        env = dict(os.environ, EPICS_CAS_SERVER_PORT=str(port), EPICS_CAS_INTF_ADDR_LIST="127.0.0.1")
        r = subprocess.run([str(BEAMCTL), "softioc", "-m", f"P={ioc.prefix}", "--acf", str(bad),
                            str(db)], capture_output=True, text=True, timeout=20, env=env)
    finally:
        release_port(port)
    assert r.returncode != 0, "a bad ACF must stop the server from starting"
    assert "bad.acf" in r.stderr, f"the error must name the file, got {r.stderr!r}"
    assert "ready:" not in r.stdout


def test_the_control_room_example_lets_only_operators_there_move_motors(ioc):
    """docs/softioc.md's example ACF (examples/acf/control_room.acf): a motor record in group MOTORS
    is writable only for an operator's user name on a control-room host; everyone reads it; other
    records stay writable."""
    from pathlib import Path
    acf = Path(__file__).resolve().parents[2] / "examples" / "acf" / "control_room.acf"
    db = """
record(motor, "$(P)m1") { field(DTYP, "Sim Motor") field(ASG, "MOTORS") field(MRES, "0.001") }
record(ao, "$(P)other") { field(VAL, "1") field(PINI, "YES") }
"""
    s = ioc.start(db, acf=str(acf))
    m1, other = ioc.prefix + "m1", ioc.prefix + "other"
    cases = [("opr1", "cr-ws1", 3), ("opr2", "CR-WS2", 3), ("guest", "cr-ws1", 1), ("opr1", "laptop", 1)]
    for user, host, access in cases:
        with raw.Circuit("127.0.0.1", s.port, user=user, hostname=host) as c:
            assert c.create(m1)["access"] == access, (user, host)
            assert c.create(other)["access"] == 3, (user, host)
