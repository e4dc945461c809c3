"""`beamctl signals ioc.yaml [PATTERN]`: the IOC's signal registry (name, type, direction, owner,
writer, PV), read from the configuration without touching a bus; every PV it names is served by
`beamctl run`, and an output whose writer is an axis refuses a CA put (one writer per output)."""

import subprocess

import re

import epics
import pytest

from conftest import BEAMCTL, REPO_ROOT, require_binary

DEMO = REPO_ROOT / "examples" / "demo" / "ioc.yaml"


def signals(*args):
    require_binary()
    return subprocess.run([str(BEAMCTL), "signals", *map(str, args)], capture_output=True, text=True, timeout=60)


def rows(text):
    """{name: (type, direction, owner, writer, pv)} of the table (columns split on 2+ blanks)."""
    out = {}
    lines = text.splitlines()
    assert lines[0].split() == ["NAME", "TYPE", "DIR", "OWNER", "WRITER", "PV"], lines[0]
    for line in lines[1:]:
        cols = re.split(r"\s{2,}", line.strip())
        out[cols[0]] = tuple(cols[1:])
    return out


def test_the_demo_lists_bus_axis_and_plc_signals_with_their_writers():
    r = signals(DEMO)
    assert r.returncode == 0, r.stderr
    t = rows(r.stdout)
    assert t["ec0.s11.driveControl01"] == ("UINT16", "output", "ec0", "axis 1 (SlitTop)", "DEMO:m0s011-driveControl01")
    assert t["ec0.s1.binaryInput01"] == ("BOOL", "input", "ec0", "-", "DEMO:m0s001-BI01")
    assert t["ax1.enc.actpos"] == ("LREAL", "input", "axis 1 (SlitTop)", "-", "DEMO:SlitTop-PosAct")
    assert t["ax1.traj.extsetpos"][1] == "variable"
    assert t["plc0.enable"] == ("LREAL", "variable", "plc0", "-", "DEMO:PLC00-EnaCmd")
    # an output nobody drives is written through its PV
    free = [n for n, v in t.items() if v[1] == "output" and v[3] == "CA (its PV)"]
    assert free, "the demo has free outputs (the digital outputs of s3)"


def test_a_pattern_selects_and_one_that_matches_nothing_exits_1():
    r = signals(DEMO, "ax2.traj.*")
    assert r.returncode == 0, r.stderr
    names = list(rows(r.stdout))
    assert names and all(n.startswith("ax2.traj.") for n in names), names
    r = signals(DEMO, "ec9.*")
    assert r.returncode == 1
    assert rows(r.stdout) == {}


def test_a_bad_configuration_is_reported_not_listed(tmp_path):
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text("ioc: {name: X}\nbuses:\n  - id: 0\n    link: {type: sim}\n    slaves:\n      - {position: 0, type: EL9999}\n")
    r = signals(cfg)
    assert r.returncode == 1
    assert "unknown device type 'EL9999'" in r.stderr, r.stderr


@pytest.mark.usefixtures("demo")
def test_every_pv_the_registry_names_is_served_and_axis_outputs_are_read_only():
    t = rows(signals(DEMO).stdout)
    pvs = sorted({v[4] for n, v in t.items()
                  if v[4] != "-" and (n.startswith("ec0.s11.") or n.startswith("ax1.") or n.startswith("plc0."))})
    assert len(pvs) > 10, pvs
    for name in pvs:
        assert epics.caget(name, timeout=5) is not None, name
    # the drive control word of SlitTop is the axis's: CA may only read it, DESC names the writer
    out = epics.PV(t["ec0.s11.driveControl01"][4])
    assert out.wait_for_connection(5)
    assert not out.write_access
    assert epics.caget(out.pvname + ".DESC") == "set by axis 1 (SlitTop)"
    # a free output (no writer but its PV) is writable
    free = next(v[4] for n, v in t.items() if v[1] == "output" and v[3] == "CA (its PV)")
    pv = epics.PV(free)
    assert pv.wait_for_connection(5) and pv.write_access, free
