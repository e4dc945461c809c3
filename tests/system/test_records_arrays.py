"""The array record types (aai, aao, subArray, compress, histogram), printf, and sub/aSub with
routines from a library loaded by `dlload`, seen by a real EPICS client (pyepics on libca)
talking to `beamctl softioc`: arrays written and read whole through CA, NORD/NUSE, windows,
compression, counts, and a startup script that loads routines.

Every test serves its own small .db (through the `ioc` fixture, PV names prefixed with the
test's unique $(P))."""

from pathlib import Path

import pytest

from conftest import BEAMCTL, connect, wait_for

import epics
from epics import ca, dbr


def caget(name, **kw):
    kw.setdefault("timeout", 5)
    kw.setdefault("use_monitor", False)
    return epics.caget(name, **kw)


def caput(name, value, **kw):
    kw.setdefault("timeout", 10)
    kw.setdefault("wait", True)
    return epics.caput(name, value, **kw)


def as_list(v):
    return [float(x) for x in v]


def test_aao_writes_an_array_that_aai_reads_through_a_link(ioc, prefix):
    ioc.start("""
record(aao, "$(P)out") { field(NELM, "8") field(FTVL, "DOUBLE") field(OUT, "$(P)wf PP") }
record(waveform, "$(P)wf") { field(NELM, "8") field(FTVL, "LONG") field(FLNK, "$(P)in") }
record(aai, "$(P)in") { field(NELM, "8") field(FTVL, "SHORT") field(INP, "$(P)wf") }
""")
    p = prefix
    assert caput(p + "out", [1.5, 2, 3, 4]) == 1
    assert as_list(caget(p + "out", count=4)) == [1.5, 2, 3, 4]
    assert caget(p + "out.NORD") == 4
    assert as_list(caget(p + "wf", count=4)) == [1, 2, 3, 4]  # LONG elements
    assert as_list(caget(p + "in", count=4)) == [1, 2, 3, 4]
    assert caget(p + "in.NORD") == 4
    assert caget(p + "in.SEVR", as_string=True) == "NO_ALARM"
    assert caget(p + "in.FTVL", as_string=True) == "SHORT"
    chan = epics.PV(p + "in")
    assert chan.wait_for_connection(5)
    assert chan.nelm == 8


def test_subarray_window_follows_indx_and_nelm(ioc, prefix):
    ioc.start("""
record(waveform, "$(P)wf") { field(NELM, "10") field(FTVL, "DOUBLE") }
record(subArray, "$(P)sa") { field(INP, "$(P)wf") field(MALM, "10") field(NELM, "3") field(INDX, "2") }
""")
    p = prefix
    assert caput(p + "wf", [0, 1, 2, 3, 4, 5, 6, 7]) == 1
    assert caput(p + "sa.PROC", 1) == 1
    assert as_list(caget(p + "sa", count=3)) == [2, 3, 4]
    assert caput(p + "sa.INDX", 6) == 1  # processes the record
    assert caget(p + "sa.NORD") == 2
    assert as_list(caget(p + "sa", count=2)) == [6, 7]


def test_compress_circular_buffer_and_histogram_counts(ioc, prefix):
    ioc.start("""
record(ao, "$(P)x") { field(FLNK, "$(P)fan") }
record(fanout, "$(P)fan") { field(LNK1, "$(P)buf") field(LNK2, "$(P)avg") field(LNK3, "$(P)h") }
record(compress, "$(P)buf") { field(INP, "$(P)x") field(ALG, "Circular Buffer") field(NSAM, "4") }
record(compress, "$(P)avg") { field(INP, "$(P)x") field(ALG, "N to 1 Average") field(N, "2") field(NSAM, "4") }
record(histogram, "$(P)h") { field(SVL, "$(P)x") field(NELM, "5") field(LLIM, "0") field(ULIM, "10") }
""")
    p = prefix
    for v in (1, 3, 5, 7, 9):
        assert caput(p + "x", v) == 1
    assert caget(p + "buf.NUSE") == 4
    assert as_list(caget(p + "buf", count=4)) == [3, 5, 7, 9]  # oldest dropped
    assert as_list(caget(p + "avg", count=2)) == [2, 6]
    assert [int(c) for c in caget(p + "h", count=5)] == [1, 1, 1, 1, 1]
    assert caput(p + "h.CMD", "Clear") == 1
    assert [int(c) for c in caget(p + "h", count=5)] == [0, 0, 0, 0, 0]
    assert caput(p + "buf.RES", 1) == 1
    assert caget(p + "buf.NUSE") == 0


def test_printf_formats_inputs(ioc, prefix):
    ioc.start("""
record(ao, "$(P)t") { field(VAL, "21.456") }
record(longout, "$(P)n") { field(VAL, "3") }
record(printf, "$(P)msg") { field(FMT, "T=%.1f n=%d (%x)") field(INP0, "$(P)t") field(INP1, "$(P)n") field(INP2, "$(P)n") }
""")
    p = prefix
    assert caput(p + "msg.PROC", 1) == 1
    assert caget(p + "msg", as_string=True) == "T=21.5 n=3 (3)"


def test_long_strings_are_one_string_and_the_char_array_with_dollar(ioc, prefix):
    """lsi/lso/printf VAL as softIoc serves it: "VAL" one DBR_STRING (its first 39 characters),
    "VAL$" the char array whole (caget -S)."""
    ioc.start("""
record(lso, "$(P)lso") { field(SIZV, "120") }
record(lsi, "$(P)lsi") { field(SIZV, "120") field(INP, "$(P)lso") }
record(printf, "$(P)pf") { field(FMT, "%s; and then more text from the format") field(INP0, "$(P)lso") field(SIZV, "120") }
""")
    p = prefix
    text = "a long string of more than forty characters, as a beamline name can be"
    chid = connect(p + "lso")
    assert ca.field_type(chid) == dbr.STRING
    assert ca.element_count(chid) == 1
    whole = connect(p + "lso.VAL$")
    assert ca.field_type(whole) == dbr.CHAR
    assert ca.element_count(whole) == 120
    assert caput(p + "lso.VAL$", text, wait=True) == 1
    assert caget(p + "lso") == text[:39]
    assert caget(p + "lso.VAL$", as_string=True) == text
    assert caget(p + "lso.LEN") == len(text) + 1
    assert caput(p + "lsi.PROC", 1, wait=True) == 1
    assert caget(p + "lsi.VAL$", as_string=True) == text  # a link to a char array: whole
    assert caput(p + "pf.PROC", 1, wait=True) == 1
    # %s of a link to lso (not lso.VAL$): its DBR_STRING, 39 characters (dbGetLinkLS)
    formatted = text[:39] + "; and then more text from the format"
    assert caget(p + "pf") == formatted[:39]
    assert caget(p + "pf.VAL$", as_string=True) == formatted
    assert caput(p + "lso", "short", wait=True) == 1  # a DBR_STRING put
    assert caget(p + "lso.VAL$", as_string=True) == "short"
    assert caget(p + "lso.LEN") == 6


ROUTINES = Path(str(BEAMCTL)).parent / "tests" / "unit" / "record_routines_plugin.so"


def test_sub_and_asub_routines_from_a_dlload_library(ioc, prefix, tmp_path):
    if not ROUTINES.exists():
        pytest.skip(f"{ROUTINES} not built (bbuild release record_routines_plugin)")
    (tmp_path / "sub.db").write_text("""
record(ao, "$(P)x") { field(VAL, "2") }
record(sub, "$(P)s") { field(SNAM, "sub_sum") field(INPA, "$(P)x") field(INPB, "40") }
record(waveform, "$(P)wf") { field(NELM, "4") }
record(aSub, "$(P)a") {
    field(SNAM, "asub_scale") field(INPA, "$(P)wf") field(NOA, "4") field(INPB, "10")
    field(NOVA, "4") field(OUTA, "$(P)res PP")
}
record(waveform, "$(P)res") { field(NELM, "4") }
""")
    (tmp_path / "st.cmd").write_text(f"""dlload {ROUTINES}
dbLoadRecords sub.db "P={prefix}"
iocInit
""")
    ioc.start(db_files=[tmp_path / "st.cmd"])
    p = prefix
    assert caput(p + "s.PROC", 1) == 1
    assert caget(p + "s") == 42
    assert caput(p + "wf", [1, 2, 3]) == 1
    assert caput(p + "a.PROC", 1) == 1
    assert as_list(caget(p + "res", count=3)) == [10, 20, 30]
    assert caget(p + "a.NEVA") == 3
    assert caget(p + "a.SEVR", as_string=True) == "NO_ALARM"


def test_an_snam_no_library_provides_fails_only_its_record(ioc, prefix):
    """As EPICS: the IOC starts and serves; the error names the record and the routine; only that
    record fails (BAD_SUB/INVALID when processed)."""
    p = prefix
    srv = ioc.start('record(sub, "$(P)s") { field(SNAM, "not_there") }\n'
                    'record(ai, "$(P)fine") { field(VAL, "3") }\n')
    assert f"record {p}s: SNAM 'not_there'" in srv.stderr(), srv.stderr()
    assert caput(p + "s.PROC", 1, wait=True) == 1
    assert caget(p + "s.STAT") == 16  # BAD_SUB (menuAlarmStat has more choices than CA's 16 enum strings)
    assert caget(p + "s.SEVR", as_string=True) == "INVALID"
    assert caget(p + "fine") == 3


def test_plugin_option_loads_routines_and_an_unknown_snam_lists_them(prefix, tmp_path):
    if not ROUTINES.exists():
        pytest.skip(f"{ROUTINES} not built")
    from conftest import acquire_port, release_port, DEFAULT_SIGINT
    import subprocess
    (tmp_path / "p.db").write_text('record(sub, "$(P)ok") { field(SNAM, "sub_sum") }\n'
                                   'record(sub, "$(P)bad") { field(SNAM, "sub_summ") }\n')
    port = acquire_port()
    env = {"EPICS_CAS_SERVER_PORT": str(port), "EPICS_CAS_INTF_ADDR_LIST": "127.0.0.1", "PATH": "/usr/bin:/bin"}
    proc = subprocess.Popen(DEFAULT_SIGINT + [str(BEAMCTL), "softioc", "-P", str(ROUTINES), "-m", f"P={prefix}", "-d",
                                              "p.db"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, cwd=str(tmp_path), env=env, text=True)
    try:
        lines = [proc.stdout.readline() for _ in range(2)]  # "shell: ..." then "ready: ..."
        assert any(line.startswith("ready:") for line in lines), lines  # serves though one record cannot work
        bad = subprocess.run([str(BEAMCTL), "softioc", "-P", str(tmp_path / "p.db"), "-d", "p.db"],
                             capture_output=True, text=True, timeout=30, cwd=str(tmp_path), env=env)
    finally:
        proc.terminate()
        try:
            _out, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            _out, err = proc.communicate()
        release_port(port)
    assert f"record {prefix}bad: SNAM 'sub_summ'" in err, err
    assert f"{ROUTINES} (sub_sum sub" in err, err  # -P loaded the library
    assert f"record {prefix}ok" not in err
    assert bad.returncode != 0 and f"{tmp_path / 'p.db'}: cannot load" in bad.stderr, bad.stderr


def test_arrays_through_ca_links_between_two_servers(ioc, prefix):
    p = prefix
    b = ioc.start("""record(waveform, "$(P)B:wf") { field(NELM, "6") field(FTVL, "DOUBLE") }""")
    ioc.start("""
record(aai, "$(P)A:in") { field(NELM, "6") field(FTVL, "LONG") field(INP, "$(P)B:wf CP") }
record(compress, "$(P)A:max") { field(INP, "$(P)B:wf CP") field(ALG, "N to 1 High Value") field(N, "3") field(NSAM, "4") }
record(aao, "$(P)A:out") { field(NELM, "3") field(OUT, "$(P)B:wf CA") }
""", extra_env={"EPICS_CA_ADDR_LIST": f"127.0.0.1:{b.port}", "EPICS_CA_AUTO_ADDR_LIST": "NO"})
    assert caput(p + "B:wf", [1, 5, 2, 7, 3, 4]) == 1
    assert wait_for(lambda: caget(p + "A:in.NORD") == 6, timeout=30)
    assert as_list(caget(p + "A:in", count=6)) == [1, 5, 2, 7, 3, 4]
    # base 7.0.8: an array of at least N elements is compressed whole into one sample
    assert wait_for(lambda: caget(p + "A:max.NUSE") == 1, timeout=30)
    assert as_list(caget(p + "A:max", count=1)) == [7]
    assert caput(p + "A:out", [9, 8, 7]) == 1  # written over CA to B
    assert wait_for(lambda: caget(p + "B:wf.NORD") == 3, timeout=30)
    assert as_list(caget(p + "B:wf", count=3)) == [9, 8, 7]
