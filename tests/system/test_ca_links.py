"""CA links between two `beamctl softioc` processes (as EPICS dbCa), seen with pyepics: IOC A
links to records of IOC B on another port. A CP input link processes A on each change of B and
carries B's severity (MS); a CA output link writes B; when B is killed A's record goes
LINK/INVALID; when B comes back on the same port the link reconnects and values flow again.

Waits are for events, with generous limits (shared 2-core VMs); nothing asserts a duration."""

import epics

from conftest import connect, wait_for
from epics import ca, dbr

LINK_ALARM = 14
INVALID = 3
MAJOR = 2

DB_B = """
record(ao, "$(P)B:val") { field(VAL, "1") field(HIGH, "5") field(HSV, "MAJOR") }
record(ao, "$(P)B:sink") { field(VAL, "0") }
record(calc, "$(P)B:count") { field(CALC, "VAL+1") }
record(ao, "$(P)B:slow") { field(FLNK, "$(P)B:delay") }
record(calcout, "$(P)B:delay") { field(INPA, "$(P)B:slow") field(CALC, "A") field(ODLY, "3") field(OUT, "$(P)B:done PP") }
record(ao, "$(P)B:done") {}
"""

DB_A = """
record(ai, "$(P)A:in") { field(INP, "$(P)B:val CP MS") }
record(calc, "$(P)A:seen") { field(INPA, "$(P)B:val CP") field(INPB, "$(P)A:seen") field(CALC, "B+1") }
record(ao, "$(P)A:out") { field(OUT, "$(P)B:sink CA") field(FLNK, "$(P)B:count.PROC CA") }
record(ao, "$(P)A:async") { field(DTYP, "Async Soft Channel") field(OUT, "$(P)B:slow CA") field(FLNK, "$(P)A:after") }
record(calc, "$(P)A:after") { field(CALC, "VAL+1") }
"""


def get(name, **kw):
    kw.setdefault("timeout", 10)
    kw.setdefault("use_monitor", False)
    return epics.caget(name, **kw)


def put(name, value):
    return epics.caput(name, value, wait=True, timeout=20)


def start_pair(ioc):
    b = ioc.start(DB_B)
    # A's CA client searches B's port only (its own server is on another one).
    a = ioc.start(DB_A, extra_env={"EPICS_CA_ADDR_LIST": f"127.0.0.1:{b.port}", "EPICS_CA_AUTO_ADDR_LIST": "NO"})
    return a, b


def test_cp_link_processes_on_each_change_and_carries_the_severity(ioc, prefix):
    p = prefix
    a, b = start_pair(ioc)
    assert wait_for(lambda: get(p + "A:in") == 1, timeout=30), a.stderr()[-2000:]
    # The link field reads as EPICS prints it.
    assert ca.get(connect(p + "A:in.INP"), ftype=dbr.STRING) == p + "B:val CP MS"
    seen0 = get(p + "A:seen")
    for k, v in enumerate([2, 3, 4], start=1):
        assert put(p + "B:val", v) == 1
        assert wait_for(lambda: get(p + "A:in") == v, timeout=30)
        assert wait_for(lambda: get(p + "A:seen") >= seen0 + k, timeout=30)
    assert get(p + "A:seen") == seen0 + 3  # once per change
    assert put(p + "B:val", 7) == 1  # above B's HIGH: MAJOR, propagated by MS
    assert wait_for(lambda: get(p + "A:in") == 7, timeout=30)
    assert get(p + "A:in.SEVR") == MAJOR
    assert get(p + "A:in.STAT") == LINK_ALARM
    assert put(p + "B:val", 2) == 1
    assert wait_for(lambda: get(p + "A:in.SEVR") == 0, timeout=30)


def test_ca_output_and_forward_links_write_the_other_ioc(ioc, prefix):
    p = prefix
    a, b = start_pair(ioc)
    assert wait_for(lambda: get(p + "A:in") == 1, timeout=30)  # A's links are up
    count0 = get(p + "B:count")
    assert put(p + "A:out", 3.5) == 1
    assert wait_for(lambda: get(p + "B:sink") == 3.5, timeout=30), a.stderr()[-2000:]
    assert wait_for(lambda: get(p + "B:count") == count0 + 1, timeout=30)  # FLNK .PROC CA
    assert get(p + "A:out.SEVR") == 0


def test_async_soft_channel_output_completes_when_the_other_ioc_has(ioc, prefix):
    """devAoSoftCallback: A's put-callback ends only once B's processing of the put (a calcout
    that writes B:done after its 3 s ODLY) has completed; A's FLNK runs then too."""
    p = prefix
    a, b = start_pair(ioc)
    assert wait_for(lambda: get(p + "A:in") == 1, timeout=30)  # A's links are up
    assert get(p + "A:after") == 0
    assert put(p + "A:async", 4) == 1
    assert get(p + "B:done") == 4, a.stderr()[-2000:]  # B finished before A reported done
    assert get(p + "A:after") == 1
    assert get(p + "A:async.PACT") == 0
    assert get(p + "A:async.SEVR") == 0


def test_link_goes_invalid_when_the_other_ioc_dies_and_reconnects_when_it_returns(ioc, prefix):
    p = prefix
    a, b = start_pair(ioc)
    assert wait_for(lambda: get(p + "A:in") == 1, timeout=30)
    b.kill()
    assert wait_for(lambda: get(p + "A:in.SEVR") == INVALID, timeout=60), a.stderr()[-2000:]
    assert get(p + "A:in.STAT") == LINK_ALARM
    put(p + "A:out", 5)  # cannot be written: the output record says so
    assert wait_for(lambda: get(p + "A:out.SEVR") == INVALID, timeout=30)

    b.start()  # same port
    assert wait_for(lambda: get(p + "A:in.SEVR") == 0 and get(p + "A:in") == 1, timeout=60), a.stderr()[-2000:]
    assert wait_for(lambda: put(p + "B:val", 8) == 1, timeout=30)
    assert wait_for(lambda: get(p + "A:in") == 8, timeout=30)
    assert get(p + "A:in.SEVR") == MAJOR
    assert put(p + "A:out", 6) == 1
    assert wait_for(lambda: get(p + "B:sink") == 6, timeout=30)
    assert a.alive()


def test_beamctl_run_db_files_have_ca_links_too(ioc, prefix, tmp_path):
    from conftest import RunServer, acquire_port, release_port
    p = prefix
    b = ioc.start(DB_B)
    (tmp_path / "a.db").write_text(DB_A)
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(f'ioc: {{name: RUNA, prefix: "{p}R:"}}\ndb:\n  - {{file: a.db, macros: {{P: "{p}"}}}}\n')
    port = acquire_port()
    run = RunServer(tmp_path, cfg, port)
    run.extra_env = {"EPICS_CA_ADDR_LIST": f"127.0.0.1:{b.port}", "EPICS_CA_AUTO_ADDR_LIST": "NO"}
    try:
        run.start()
        assert wait_for(lambda: get(p + "A:in") == 1, timeout=30), run.stderr()[-2000:]
        assert put(p + "B:val", 3) == 1
        assert wait_for(lambda: get(p + "A:in") == 3, timeout=30)
        assert put(p + "A:out", 4.5) == 1
        assert wait_for(lambda: get(p + "B:sink") == 4.5, timeout=30)
        assert run.stop() == 0  # a clean stop with the CA client open
    finally:
        run.kill()
        release_port(port)
