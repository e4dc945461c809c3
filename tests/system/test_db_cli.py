"""`beamctl db` prints the loaded database; bad .db input is a load error with file:line:col on
stderr and a non-zero exit, for `db` and for `softioc` alike."""

import os
import re
import subprocess

import pytest

from conftest import BEAMCTL, acquire_port, release_port, require_binary

GOOD = r"""# a comment line
record(ai, "$(P)temp") {
    field(DESC, "Temperature")   # trailing comment
    field(EGU, "degC")
    field(PREC, "2")
    field(HOPR, "100")
    field(LOPR, "-20.5")
    field(HIHI, "90") field(HHSV, "MAJOR")
    field(MDEL, "-1")
    field(SCAN, "1 second")
}

record(bo, "${P}$(R)sw") {
    field(ZNAM, "Off")
    field(ONAM, "On")
    field(OSV, "MINOR")
}
record(mbbo, "$(P)mode") { field(ZRST, "A") field(ONST, "B b") field(ONVL, "7") }
record(waveform, "$(P)wf") { field(FTVL, "FLOAT") field(NELM, "16") }
record(stringout, "$(P)$(S=dflt)") { field(VAL, "with \"quotes\"") field(ASG, "RO") }
record(longin, "$(P)li") { field(VAL, "-5") field(PINI, "YES") }
"""

EXPECTED = {
    ("ai", "X:temp"): {"DESC": "Temperature", "EGU": "degC", "PREC": "2", "HOPR": "100",
                       "LOPR": "-20.5", "HIHI": "90", "HHSV": "MAJOR", "MDEL": "-1",
                       "SCAN": "1 second"},
    ("bo", "X:ysw"): {"ZNAM": "Off", "ONAM": "On", "OSV": "MINOR"},
    ("mbbo", "X:mode"): {"ZRST": "A", "ONST": "B b", "ONVL": "7"},
    ("waveform", "X:wf"): {"FTVL": "FLOAT", "NELM": "16"},
    ("stringout", "X:dflt"): {"VAL": 'with \\"quotes\\"', "ASG": "RO"},
    ("longin", "X:li"): {"VAL": "-5", "PINI": "YES"},
}

REC_RE = re.compile(r'record\(\s*(\w+)\s*,\s*"((?:[^"\\]|\\.)*)"\s*\)\s*\{(.*?)\n?\}', re.S)
FIELD_RE = re.compile(r'field\(\s*(\w+)\s*,\s*"((?:[^"\\]|\\.)*)"\s*\)')


def parse_db(text):
    out = {}
    for m in REC_RE.finditer(text):
        out[(m.group(1), m.group(2))] = dict(FIELD_RE.findall(m.group(3)))
    return out


def same_value(a, b):
    if a == b:
        return True
    try:
        return float(a) == float(b)
    except ValueError:
        return False


def run(*args, timeout=20):
    require_binary()
    return subprocess.run([str(BEAMCTL), *args], capture_output=True, text=True, timeout=timeout)


def test_db_prints_loaded_database(tmp_path):
    src = tmp_path / "good.db"
    src.write_text(GOOD)
    r = run("db", "-m", "P=X:,R=y", str(src))
    assert r.returncode == 0, r.stderr
    got = parse_db(r.stdout)
    assert set(got) == set(EXPECTED), f"records: {sorted(got)}"
    for key, fields in EXPECTED.items():
        for f, v in fields.items():
            assert f in got[key], f"{key}: field {f} missing from output"
            assert same_value(got[key][f], v), f"{key}.{f}: {got[key][f]!r}, want {v!r}"
    # the output is itself a valid .db that loads to the same database
    again = tmp_path / "again.db"
    again.write_text(r.stdout)
    r2 = run("db", str(again))
    assert r2.returncode == 0, r2.stderr
    assert parse_db(r2.stdout) == got
    assert r2.stdout == r.stdout, "printing is a fixed point"


def test_db_several_files(tmp_path):
    a = tmp_path / "a.db"
    b = tmp_path / "b.db"
    a.write_text('record(ai, "$(P)one") { }\n')
    b.write_text('record(ao, "$(P)two") { field(DRVH, "3") }\n')
    r = run("db", "-m", "P=Q:", str(a), str(b))
    assert r.returncode == 0, r.stderr
    got = parse_db(r.stdout)
    assert set(got) == {("ai", "Q:one"), ("ao", "Q:two")}
    assert same_value(got[("ao", "Q:two")]["DRVH"], "3")


BAD = [  # (name, text, line, allowed columns: statement start or offending token; None = any)
    ("unknown_record_type", 'record(ai, "ok") { }\n\nrecord(bogusrec, "c") { }\n', 3, (1, 8)),
    ("unknown_field", 'record(ai, "a") {\n    field(EGU, "x")\n    field(FOO, "1")\n}\n', 3,
     (5, 11)),
    ("field_of_other_type", 'record(ai, "a") {\n    field(ZNAM, "x")\n}\n', 2, (5, 11)),
    ("bad_number", 'record(ai, "a") {\n  field(PREC, "abc")\n}\n', 2, None),
    ("bad_menu_choice", 'record(ai, "a") {\n  field(SCAN, "3 second")\n}\n', 2, None),
    ("bad_ftvl", 'record(waveform, "w") {\n  field(FTVL, "QUAD")\n}\n', 2, None),
    ("unterminated_record", 'record(ai, "a") {\n  field(EGU, "x")\n', None, None),
    ("missing_quote", 'record(ai, "a) {\n}\n', 1, None),
    ("garbage", 'hello world\n', 1, (1,)),
]


def check_error(stderr, path, line, col):
    pat = re.compile(r"(?:%s|%s):(\d+):(\d+): \S" % (re.escape(str(path)),
                                                      re.escape(os.path.basename(path))))
    m = pat.search(stderr)
    assert m, f"stderr should have 'file:line:col: message', got {stderr!r}"
    if line is not None:
        assert int(m.group(1)) == line, f"line {m.group(1)}, want {line}: {stderr!r}"
    if col is not None:
        assert int(m.group(2)) in col, f"column {m.group(2)}, want one of {col}: {stderr!r}"


@pytest.mark.parametrize("name,text,line,col", BAD, ids=[b[0] for b in BAD])
def test_db_load_errors(tmp_path, name, text, line, col):
    path = tmp_path / f"{name}.db"
    path.write_text(text)
    r = run("db", str(path))
    assert r.returncode != 0, f"{name}: must fail, stdout={r.stdout!r}"
    check_error(r.stderr, path, line, col)


@pytest.mark.parametrize("name,text,line,col", BAD[:3], ids=[b[0] for b in BAD[:3]])
def test_softioc_refuses_bad_db(tmp_path, name, text, line, col):
    path = tmp_path / f"{name}.db"
    path.write_text(text)
    port = acquire_port()
    try:
        env = dict(os.environ, EPICS_CAS_SERVER_PORT=str(port),
                   EPICS_CAS_INTF_ADDR_LIST="127.0.0.1")
        require_binary()
        r = subprocess.run([str(BEAMCTL), "softioc", str(path)], capture_output=True, text=True,
                           timeout=20, env=env)
    finally:
        release_port(port)
    assert r.returncode != 0
    assert "ready:" not in r.stdout
    check_error(r.stderr, path, line, col)
