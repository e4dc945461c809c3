"""Record links and processing seen by a real EPICS client (pyepics on libca) talking to
`beamctl softioc`: forward links, CP links, calcout output delays and options, seq delays,
maximize-severity propagation, link fields over CA (read back, relink, refused relink),
SDIS/DISV disabling, link load errors, periodic scans, dfanout and sel.

Every test serves its own small .db (through the `ioc` fixture, PV names prefixed with the
test's unique $(P)). Timing checks are counts with generous bounds or lower bounds on elapsed
time, never tight deadlines: these run on shared 2-core VMs."""

import os
import re
import subprocess
import time

import pytest

import ca_raw as raw
from conftest import BEAMCTL, ECA_NORMAL, ECA_PUTFAIL, acquire_port, connect, put_status, release_port, require_binary, subscribe, wait_for

import epics
from epics import ca, dbr


def caget(name, **kw):
    kw.setdefault("timeout", 5)
    kw.setdefault("use_monitor", False)
    return epics.caget(name, **kw)


def caput(name, value, **kw):
    kw.setdefault("timeout", 10)
    return epics.caput(name, value, **kw)


def get_str(name):
    """The value as the server converts it to DBR_STRING (a menu field reads as its choice's
    name even past the 16 states a DBR_CTRL_ENUM can carry, which pyepics' as_string uses)."""
    return ca.get(connect(name), ftype=dbr.STRING)


def monitor(name):
    """A VAL-only (DBE_VALUE) monitor on `name`: (collector, handle) once the first event came."""
    col, handle = subscribe(connect(name), mask=dbr.DBE_VALUE)
    assert col.wait_count(1), f"no initial monitor event for {name}"
    return col, handle


def settle(col, seconds=0.5):
    """Pumps libca for `seconds`, so late (unexpected) monitor events would be collected."""
    wait_for(lambda: False, timeout=seconds)
    return col.values()


# ---------------------------------------------------------------------------------------------
# 1. FLNK chain ao -> calc -> calc
# ---------------------------------------------------------------------------------------------
def test_forward_link_chain_processes_calcs_once_per_put(ioc, prefix):
    ioc.start("""
record(ao, "$(P)ao") { field(FLNK, "$(P)c1") }
record(calc, "$(P)c1") { field(INPA, "$(P)ao") field(CALC, "A*2") field(FLNK, "$(P)c2") }
record(calc, "$(P)c2") { field(INPA, "$(P)c1") field(CALC, "A+1") }
""")
    p = prefix
    # the last calc was never processed: UDF/INVALID
    assert caget(p + "c2.SEVR", as_string=True) == "INVALID"
    pv = epics.PV(p + "c2", auto_monitor=dbr.DBE_VALUE)
    seen = []
    pv.add_callback(lambda value=None, **kw: seen.append(value))
    assert pv.wait_for_connection(5)
    wait_for(lambda: False, timeout=0.5)
    n0 = len(seen)  # the first monitor event (the value at connection), if pyepics passed it on
    assert n0 <= 1, seen

    for i, v in enumerate((3, 4, 5), start=1):
        assert caput(p + "ao", v, wait=True) == 1
        assert caget(p + "c1") == 2 * v
        assert caget(p + "c2") == 2 * v + 1
        assert wait_for(lambda: len(seen) >= n0 + i, 5), f"no monitor update after put {i}: {seen}"
    wait_for(lambda: False, timeout=0.5)
    assert seen[n0:] == [7.0, 9.0, 11.0], "exactly one update of the last calc per put"
    assert caget(p + "c2.SEVR", as_string=True) == "NO_ALARM"
    pv.clear_callbacks()
    pv.disconnect()


# ---------------------------------------------------------------------------------------------
# 2. CP input link
# ---------------------------------------------------------------------------------------------
def test_cp_link_processes_the_calc_on_every_change_of_its_source(ioc, prefix):
    ioc.start("""
record(ao, "$(P)src") { }
record(calc, "$(P)follow") { field(INPA, "$(P)src CP") field(CALC, "A*10") }
""")
    p = prefix
    col, _h = monitor(p + "follow")
    base = col.count()
    for i, v in enumerate((1, 2, 3.5), start=1):
        assert caput(p + "src", v, wait=True) == 1
        assert col.wait_value(lambda x, v=v: x == 10 * v), f"follow never showed {10 * v}: {col.values()}"
    assert caget(p + "follow") == 35
    assert caget(p + "follow.A") == 3.5
    assert settle(col)[base:] == [10.0, 20.0, 35.0]
    assert caget(p + "follow.INPA") == p + "src CP NMS"


# EPICS base 7 makes every CP/CPP input link a CA link whose first monitor event after iocInit
# processes the record (dbCa.c), so a CP-linked calc shows its source's value right after start.
def test_cp_link_processes_the_record_once_at_start_as_epics(ioc, prefix):
    ioc.start("""
record(ao, "$(P)src") { field(VAL, "4") }
record(calc, "$(P)follow") { field(INPA, "$(P)src CP") field(CALC, "A*10") }
""")
    p = prefix
    assert wait_for(lambda: caget(p + "follow") == 40, timeout=3), caget(p + "follow")
    assert caget(p + "follow.SEVR", as_string=True) == "NO_ALARM"


# ---------------------------------------------------------------------------------------------
# 3. calcout: ODLY with a put-callback, OOPT
# ---------------------------------------------------------------------------------------------
def test_calcout_output_delay_put_callback_waits_for_the_output(ioc, prefix):
    ioc.start("""
record(calcout, "$(P)co") { field(CALC, "A") field(OUT, "$(P)t PP") field(ODLY, "0.5") }
record(ao, "$(P)t") { }
""")
    p = prefix
    dlya, _h = monitor(p + "co.DLYA")
    assert dlya.values() == [0]
    tmon, _h2 = monitor(p + "t")
    t0 = time.monotonic()
    assert caput(p + "co.A", 7, wait=True) == 1
    elapsed = time.monotonic() - t0
    # right after the put returns, the output is written: the put-callback waited for it
    assert caget(p + "t") == 7
    assert caget(p + "co.OVAL") == 7
    assert caget(p + "co.DLYA") == 0
    assert elapsed >= 0.4, f"the put returned after {elapsed:.3f} s, before ODLY=0.5 could pass"
    assert tmon.wait_value(lambda x: x == 7)
    # DLYA went 0 -> 1 (during the delay) -> 0
    assert dlya.wait_count(3), dlya.values()
    assert settle(dlya, 0.3) == [0, 1, 0]
    # the target was processed by the PP write: no longer UDF
    assert caget(p + "t.SEVR", as_string=True) == "NO_ALARM"


def test_calcout_delay_is_observable_by_a_second_client(ioc, prefix):
    """While the output is delayed the target still holds its old value (seen without waiting)."""
    ioc.start("""
record(calcout, "$(P)co") { field(CALC, "A") field(OUT, "$(P)t PP") field(ODLY, "1.0") }
record(ao, "$(P)t") { field(VAL, "-1") }
""")
    p = prefix
    dlya, t = connect(p + "co.DLYA"), connect(p + "t")  # connected before the delay starts
    assert (ca.get(dlya), ca.get(t)) == (0, -1)
    done = []
    pv = epics.PV(p + "co.A", auto_monitor=False)
    assert pv.wait_for_connection(5)
    pv.put(5, callback=lambda **kw: done.append(time.monotonic()))
    # DLYA is 1 while the output waits; t still holds its old value then
    assert ca.get(dlya) == 1
    assert ca.get(t) == -1
    assert caget(p + "co") == 5, "VAL is computed at once, only the output is delayed"
    assert not done
    assert wait_for(lambda: bool(done), timeout=10), "put-callback never completed"
    assert ca.get(t) == 5
    assert ca.get(dlya) == 0


# EPICS calcoutRecord.c: with ODLY > 0 the first pass only posts DLYA; VAL, A..U and OVAL are
# posted once, after the delayed output.
def test_calcout_val_monitor_fires_only_after_the_delay_as_epics(ioc, prefix):
    ioc.start("""
record(calcout, "$(P)co") { field(CALC, "A") field(OUT, "$(P)t PP") field(ODLY, "1.0") }
record(ao, "$(P)t") { }
""")
    p = prefix
    dlya = connect(p + "co.DLYA")
    val, _h = monitor(p + "co")
    assert val.values() == [0]
    done = []
    pv = epics.PV(p + "co.A", auto_monitor=False)
    assert pv.wait_for_connection(5)
    pv.put(5, callback=lambda **kw: done.append(1))
    assert ca.get(dlya) == 1
    wait_for(lambda: False, timeout=0.3)
    during = val.values()
    assert wait_for(lambda: bool(done), timeout=10)
    assert val.wait_count(2)
    assert during == [0], f"VAL posted before the delayed output: {during}"
    assert settle(val, 0.3) == [0, 5.0]


def test_calcout_oopt_transition_to_nonzero(ioc, prefix):
    ioc.start("""
record(calcout, "$(P)co") { field(CALC, "A") field(OOPT, "Transition To Non-zero")
                            field(DOPT, "Use OCAL") field(OCAL, "A*100") field(OUT, "$(P)t PP") }
record(ao, "$(P)t") { }
""")
    p = prefix
    assert caget(p + "co.OOPT", as_string=True) == "Transition To Non-zero"
    tmon, _h = monitor(p + "t")
    assert caput(p + "co.A", 0, wait=True) == 1
    assert caget(p + "t.SEVR", as_string=True) == "INVALID", "zero: nothing written yet"
    assert caput(p + "co.A", 2, wait=True) == 1
    assert caget(p + "t") == 200, "0 -> 2 is a transition to non-zero: OCAL written"
    assert caput(p + "co.A", 3, wait=True) == 1
    assert caget(p + "t") == 200, "2 -> 3: no transition, no output"
    assert caput(p + "co.A", 0, wait=True) == 1
    assert caget(p + "t") == 200
    assert caput(p + "co.A", 1, wait=True) == 1
    assert caget(p + "t") == 100
    assert caget(p + "co") == 1
    assert settle(tmon, 0.3)[1:] == [200.0, 100.0], "t was written exactly twice"


# ---------------------------------------------------------------------------------------------
# 4. seq with a delay
# ---------------------------------------------------------------------------------------------
def test_seq_put_callback_returns_after_the_delayed_group(ioc, prefix):
    ioc.start("""
record(seq, "$(P)s") { field(DO0, "1") field(LNK0, "$(P)a PP")
                       field(DLY1, "0.5") field(DO1, "2") field(LNK1, "$(P)b PP") }
record(ao, "$(P)a") { }
record(ao, "$(P)b") { }
""")
    p = prefix
    t0 = time.monotonic()
    assert caput(p + "s.PROC", 1, wait=True) == 1
    elapsed = time.monotonic() - t0
    assert caget(p + "a") == 1
    assert caget(p + "b") == 2, "the put-callback completed before the delayed group ran"
    assert elapsed >= 0.4, f"returned after {elapsed:.3f} s although DLY1 is 0.5 s"
    assert caget(p + "a.SEVR", as_string=True) == "NO_ALARM"
    assert caget(p + "b.SEVR", as_string=True) == "NO_ALARM"
    # and again, with new values through the same groups
    assert caput(p + "s.DO1", 5, wait=True) == 1
    assert caput(p + "s.PROC", 1, wait=True) == 1
    assert caget(p + "b") == 5


# ---------------------------------------------------------------------------------------------
# 5. MS alarm propagation
# ---------------------------------------------------------------------------------------------
def test_ms_link_propagates_major_severity_with_link_status(ioc, prefix):
    ioc.start("""
record(ai, "$(P)src") { field(HIHI, "5") field(HHSV, "MAJOR") field(HIGH, "3") field(HSV, "MINOR") }
record(ai, "$(P)ms") { field(INP, "$(P)src MS") }
record(ai, "$(P)nms") { field(INP, "$(P)src NMS") }
record(ai, "$(P)mss") { field(INP, "$(P)src MSS") }
""")
    p = prefix
    assert caput(p + "src", 6, wait=True) == 1
    assert caget(p + "src.SEVR", as_string=True) == "MAJOR"
    assert caget(p + "src.STAT", as_string=True) == "HIHI"
    for r in ("ms", "nms", "mss"):
        assert caput(p + r + ".PROC", 1, wait=True) == 1
        assert caget(p + r) == 6
    assert caget(p + "ms.SEVR", as_string=True) == "MAJOR"
    assert caget(p + "ms.STAT", as_string=True) == "LINK"
    assert caget(p + "ms.SEVR") == 2 and caget(p + "ms.STAT") == 14  # MAJOR_ALARM, LINK_ALARM
    pv = epics.PV(p + "ms", form="ctrl", auto_monitor=False)
    assert pv.wait_for_connection(5)
    cv = pv.get_ctrlvars()
    assert (cv["severity"], cv["status"]) == (2, 14), cv
    pv.get(use_monitor=False)
    assert pv.severity == 2 and pv.status == 14
    assert caget(p + "nms.SEVR", as_string=True) == "NO_ALARM"
    assert caget(p + "mss.SEVR", as_string=True) == "MAJOR"
    assert caget(p + "mss.STAT", as_string=True) == "HIHI", "MSS takes the status too"
    # the source back in range: the next processing clears the propagated alarm
    assert caput(p + "src", 1, wait=True) == 1
    assert caput(p + "ms.PROC", 1, wait=True) == 1
    assert caget(p + "ms.SEVR", as_string=True) == "NO_ALARM"
    assert caget(p + "ms.STAT", as_string=True) == "NO_ALARM"
    pv.disconnect()


# ---------------------------------------------------------------------------------------------
# 6. Link fields over CA
# ---------------------------------------------------------------------------------------------
def test_link_fields_read_back_and_relink_over_ca(ioc, prefix):
    srv = ioc.start("""
record(ai, "$(P)a") { field(INP, "$(P)b.VAL PP MS") field(FLNK, "$(P)b") }
record(ai, "$(P)b") { field(VAL, "1") }
record(ai, "$(P)other") { field(VAL, "2") }
""")
    p = prefix
    assert caget(p + "a.INP") == p + "b.VAL PP MS"
    assert caget(p + "a.FLNK") == p + "b NPP NMS"
    assert caget(p + "b.INP") == ""
    assert ca.field_type(connect(p + "a.INP")) == dbr.STRING
    assert caput(p + "a.PROC", 1, wait=True) == 1
    assert caget(p + "a") == 1

    # relink to another record
    assert caput(p + "a.INP", p + "other NPP", wait=True) == 1
    assert caget(p + "a.INP") == p + "other NPP NMS"
    assert caput(p + "a.PROC", 1, wait=True) == 1
    assert caget(p + "a") == 2

    # a link to a record that does not exist is refused; pyepics does not report a failed
    # put-callback (its completion callback ignores the status): caput still returns 1 ...
    r = caput(p + "a.INP", p + "missing", wait=True)
    assert r == 1
    # ... but the old link is still there and still used
    assert caget(p + "a.INP") == p + "other NPP NMS"
    assert caput(p + "other", 3, wait=True) == 1
    assert caput(p + "a.PROC", 1, wait=True) == 1
    assert caget(p + "a") == 3
    # the protocol does say so: the WRITE_NOTIFY reply carries ECA_PUTFAIL
    with raw.Circuit("127.0.0.1", srv.port) as c:
        ch = c.create(p + "a.INP")
        assert c.write_notify(ch, [p + "missing"], dtype=raw.STRING).p1 == raw.ECA_PUTFAIL
        assert c.read(ch)[1]["value"] == [p + "other NPP NMS"]
        assert c.write_notify(ch, [p + "b MS"], dtype=raw.STRING).p1 == raw.ECA_NORMAL
    assert caget(p + "a.INP") == p + "b NPP MS"


# ---------------------------------------------------------------------------------------------
# 7. SDIS / DISV
# ---------------------------------------------------------------------------------------------
def test_sdis_disables_processing_with_disable_alarm(ioc, prefix):
    ioc.start("""
record(bo, "$(P)off") { field(VAL, "1") }
record(calc, "$(P)c") { field(CALC, "VAL+1") field(SDIS, "$(P)off") field(DISV, "1")
                        field(DISS, "MINOR") }
record(calc, "$(P)d") { field(CALC, "VAL+1") field(SDIS, "$(P)off") field(DISV, "1") }
""")
    p = prefix
    for _ in range(3):
        assert caput(p + "c.PROC", 1, wait=True) == 1, "a put-callback to a disabled record completes"
    assert caget(p + "c") == 0, "disabled: not processed"
    # DISABLE is menuAlarmStat choice 18, past the 16 strings DBR_CTRL_ENUM carries: pyepics'
    # as_string shows the number (so it does against an EPICS IOC); DBR_STRING gives the name
    assert caget(p + "c.STAT") == 18
    assert get_str(p + "c.STAT") == "DISABLE"
    assert caget(p + "c.SEVR", as_string=True) == "MINOR", "SEVR is DISS"
    assert caget(p + "c.DISA") == 1
    assert caput(p + "d.PROC", 1, wait=True) == 1
    assert caget(p + "d") == 0
    assert get_str(p + "d.STAT") == "DISABLE"
    assert caget(p + "d.SEVR", as_string=True) == "NO_ALARM", "DISS defaults to NO_ALARM"
    # enabled again: processed, the disable alarm cleared
    assert caput(p + "off", 0, wait=True) == 1
    assert caput(p + "c.PROC", 1, wait=True) == 1
    assert caget(p + "c") == 1
    assert caget(p + "c.STAT", as_string=True) == "NO_ALARM"
    assert caget(p + "c.SEVR", as_string=True) == "NO_ALARM"
    assert caget(p + "c.DISA") == 0


def test_disabled_periodic_record_does_not_count(ioc, prefix):
    ioc.start("""
record(bo, "$(P)off") { field(VAL, "1") }
record(calc, "$(P)c") { field(SCAN, ".1 second") field(CALC, "VAL+1") field(SDIS, "$(P)off") }
""")
    p = prefix
    wait_for(lambda: False, timeout=1.0)
    assert caget(p + "c") == 0
    assert get_str(p + "c.STAT") == "DISABLE"
    assert caput(p + "off", 0, wait=True) == 1
    assert wait_for(lambda: caget(p + "c") >= 3, timeout=10)
    assert caget(p + "c.STAT", as_string=True) == "NO_ALARM"


# ---------------------------------------------------------------------------------------------
# 8. Load errors
# ---------------------------------------------------------------------------------------------
def run_to_exit(args, cwd, timeout=30):
    require_binary()
    port = acquire_port()
    try:
        env = dict(os.environ, EPICS_CAS_SERVER_PORT=str(port), EPICS_CAS_INTF_ADDR_LIST="127.0.0.1")
        r = subprocess.run([str(BEAMCTL), "softioc", *map(str, args)], cwd=str(cwd), env=env,
                           capture_output=True, text=True, timeout=timeout)
    finally:
        release_port(port)
    return r.returncode, r.stdout, r.stderr


def test_link_to_missing_record_is_a_load_error(tmp_path, prefix):
    (tmp_path / "bad.db").write_text(
        f'record(ai, "{prefix}ok") {{ }}\n'
        f'record(ai, "{prefix}a") {{\n'
        f'    field(INP, "nowhere")\n'
        f'}}\n')
    rc, out, err = run_to_exit(["bad.db"], tmp_path)
    assert rc != 0, (out, err)
    assert "ready:" not in out, out
    assert re.search(r"bad\.db:3:\d+:", err), err
    assert "no record 'nowhere'" in err, err


def test_every_bad_link_is_reported(tmp_path, prefix):
    (tmp_path / "bad.db").write_text(
        f'record(calc, "{prefix}a") {{ field(INPA, "x1") field(INPB, "{prefix}b.NOPE") }}\n'
        f'record(ao, "{prefix}b") {{ field(FLNK, "x2") }}\n')
    rc, out, err = run_to_exit(["bad.db"], tmp_path)
    assert rc != 0 and "ready:" not in out
    assert "'x1'" in err and "'x2'" in err, err
    assert "has no field NOPE" in err, err
    (tmp_path / "bad2.db").write_text(
        f'record(calc, "{prefix}a") {{ field(INPB, "{prefix}b PPP") }}\n'
        f'record(ao, "{prefix}b") {{ }}\n')
    rc, out, err = run_to_exit(["bad2.db"], tmp_path)
    assert rc != 0 and "ready:" not in out
    assert re.search(r"bad2\.db:1:\d+:.*unknown link modifier 'PPP'", err), err


# ---------------------------------------------------------------------------------------------
# 9. Periodic scans
# ---------------------------------------------------------------------------------------------
def test_periodic_scan_counts(ioc, prefix):
    ioc.start("""
record(calc, "$(P)fast") { field(SCAN, ".1 second") field(CALC, "VAL+1") }
record(calc, "$(P)slow") { field(SCAN, "1 second") field(CALC, "VAL+1") }
""")
    p = prefix
    chid = connect(p + "fast")
    v0 = ca.get(chid)
    s0 = caget(p + "slow")
    wait_for(lambda: False, timeout=1.2)
    v1 = ca.get(chid)
    s1 = caget(p + "slow")
    assert 5 <= v1 - v0 <= 20, f".1 second scan counted {v1 - v0} in 1.2 s"
    assert 0 <= s1 - s0 <= 3, f"1 second scan counted {s1 - s0} in 1.2 s"
    # a monitor sees the count go up by one at a time
    col, _h = monitor(p + "fast")
    assert col.wait_count(6, timeout=10)
    vals = col.values()
    assert all(b - a == 1 for a, b in zip(vals, vals[1:])), vals
    # SCAN changed over CA: back to Passive stops the counting
    assert caput(p + "fast.SCAN", "Passive", wait=True) == 1
    wait_for(lambda: False, timeout=0.3)
    v2 = ca.get(chid)
    wait_for(lambda: False, timeout=0.5)
    assert ca.get(chid) == v2


# ---------------------------------------------------------------------------------------------
# 10. dfanout and sel
# ---------------------------------------------------------------------------------------------
def test_dfanout_writes_every_output(ioc, prefix):
    ioc.start("""
record(dfanout, "$(P)d") { field(OUTA, "$(P)p PP") field(OUTB, "$(P)q PP") field(SELM, "All") }
record(ao, "$(P)p") { }
record(ao, "$(P)q") { }
""")
    p = prefix
    assert caput(p + "d", 6.5, wait=True) == 1
    assert caget(p + "p") == 6.5
    assert caget(p + "q") == 6.5
    assert caget(p + "p.SEVR", as_string=True) == "NO_ALARM"
    assert caput(p + "d", -2, wait=True) == 1
    assert (caget(p + "p"), caget(p + "q")) == (-2, -2)


def test_sel_picks_high_low_median_of_constants(ioc, prefix):
    ioc.start("""
record(sel, "$(P)s") { field(INPA, "1") field(INPB, "5") field(INPC, "3") field(SELM, "High Signal") }
""")
    p = prefix
    assert caput(p + "s.PROC", 1, wait=True) == 1
    assert caget(p + "s") == 5
    assert caget(p + "s.SEVR", as_string=True) == "NO_ALARM"
    assert caput(p + "s.SELM", "Low Signal", wait=True) == 1
    assert caput(p + "s.PROC", 1, wait=True) == 1
    assert caget(p + "s") == 1
    assert caput(p + "s.SELM", "Median Signal", wait=True) == 1
    assert caput(p + "s.PROC", 1, wait=True) == 1
    assert caget(p + "s") == 3
    assert caget(p + "s.SELM", as_string=True) == "Median Signal"


# ---------------------------------------------------------------------------------------------
# A string read as a number (as EPICS softIoc: the read fails with ECA_GETFAIL)
# ---------------------------------------------------------------------------------------------
def test_numeric_read_of_a_string_that_holds_no_number_fails(ioc, prefix):
    ioc.start("""
record(stringin, "$(P)word") { field(VAL, "abc") }
record(stringin, "$(P)num") { field(VAL, "123") }
""")
    word, num = connect(prefix + "word"), connect(prefix + "num")
    for ftype in (dbr.SHORT, dbr.LONG, dbr.FLOAT, dbr.DOUBLE, dbr.ENUM, dbr.CHAR):
        with pytest.raises(ca.ChannelAccessGetFailure):
            ca.get(word, ftype=ftype)
    assert ca.get(word, ftype=dbr.STRING) == "abc"
    assert ca.get(num, ftype=dbr.DOUBLE) == 123
    assert ca.get(num, ftype=dbr.LONG) == 123
    with pytest.raises(ca.ChannelAccessGetFailure):  # no string is an enum index
        ca.get(num, ftype=dbr.ENUM)


def test_a_number_put_to_a_menu_field_must_index_one_of_its_choices(ioc, prefix):
    ioc.start('record(ao, "$(P)o") { field(OMSL, "supervisory") }\n')
    omsl = prefix + "o.OMSL"
    assert put_status(omsl, 1) == ECA_NORMAL
    assert get_str(omsl) == "closed_loop"
    for bad in (2, 7, 65535):  # menuOmsl has two choices
        assert put_status(omsl, bad) == ECA_PUTFAIL, bad
        assert get_str(omsl) == "closed_loop"
    assert put_status(omsl, "supervisory") == ECA_NORMAL
    assert put_status(omsl, "7") == ECA_PUTFAIL
    assert get_str(omsl) == "supervisory"
