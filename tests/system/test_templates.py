"""softIoc-style loading of a real template set (issue 41, item 3): tests/fixtures/templates is
written as ecmccfg's and synApps' templates are (macros with defaults, include, alias in a record
and at file level, info tags, a substitution file with global and pattern, ECMC's asyn addresses).
It loads offline with `beamctl db` and in `beamctl run` (ioc.yaml `db:`), where the asyn addresses
reach the axes; read with pyepics on the real libca."""

import re
import shutil
import subprocess
from pathlib import Path

import epics
from epics import ca

from conftest import BEAMCTL, REPO_ROOT, connect, require_binary, running_ioc, wait_for

FIXTURES = REPO_ROOT / "tests" / "fixtures" / "templates"
JACK = REPO_ROOT / "examples" / "demo" / "axes" / "jack.yaml"

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL7041}}
      - {{position: 2, type: EL7041}}
axes:
  - {{file: jack.yaml, macros: {{AX_ID: 1, AX_NAME: Stage, DRV_SLAVE: 1}}}}
  - {{file: jack.yaml, macros: {{AX_ID: 2, AX_NAME: Rot, DRV_SLAVE: 2}}}}
db:
  - {{file: templates/site.substitutions, macros: {{P: "{prefix}"}}}}
"""


def records(text):
    """{name: (type, {field: value}, [aliases], {info: value})} of `beamctl db` output."""
    out = {}
    for m in re.finditer(r'record\((\w+), "([^"]+)"\) \{\n(.*?)\n\}', text, re.S):
        body = m.group(3)
        fields = dict(re.findall(r'field\((\w+), "((?:[^"\\]|\\.)*)"\)', body))
        aliases = re.findall(r'alias\("([^"]+)"\)', body)
        infos = dict(re.findall(r'info\(([\w:]+), "((?:[^"\\]|\\.)*)"\)', body))
        out[m.group(2)] = (m.group(1), fields, aliases, infos)
    for rec, alias in re.findall(r'^alias\("([^"]+)", ?"([^"]+)"\)', text, re.M):
        out[rec][2].append(alias)
    return out


def test_the_set_loads_offline_with_every_macro_default_include_alias_and_info():
    require_binary()
    r = subprocess.run([str(BEAMCTL), "db", "-m", "P=OFF:", str(FIXTURES / "site.substitutions")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    recs = records(r.stdout)
    # 3 instances x (PosActRB, EnabledRB, Park from the include)
    assert sorted(recs) == sorted(f"OFF:{ax}-{s}" for ax in ("Stage", "Rot", "Spare")
                                  for s in ("PosActRB", "EnabledRB", "Park")), sorted(recs)
    typ, f, aliases, infos = recs["OFF:Stage-PosActRB"]
    assert typ == "ai"
    assert f["INP"] == "@asyn(MC_CPU1,0,1)T_SMP_MS=100/TYPE=asynFloat64/ax1.actpos?"
    assert (f["PREC"], f["EGU"], f["DESC"]) == ("3", "mm", "Actual position")  # defaults
    assert aliases == ["OFF:Stage-Position"]
    assert infos == {"autosaveFields": "DESC EGU", "archive": "monitor 1"}
    assert recs["OFF:Rot-PosActRB"][1]["EGU"] == "deg"  # the pattern's value
    assert recs["OFF:Rot-PosActRB"][1]["INP"].endswith("/ax2.actpos?")
    spare = recs["OFF:Spare-PosActRB"][1]
    assert (spare["PREC"], spare["DESC"]) == ("5", "Spare readback")
    assert recs["OFF:Rot-EnabledRB"][1]["INP"] == \
        "@asynMask(MC_CPU1,0,0x2,1)T_SMP_MS=100/TYPE=asynUInt32Digital/ax2.status?"
    park = recs["OFF:Stage-Park"]
    assert (park[1]["VAL"], park[1]["DRVH"], park[1]["DRVL"]) == ("2.5", "10", "-10")
    assert park[2] == ["OFF:Stage:PARK"]  # the file-level alias of the included template
    # the substitution file's own default of P
    r = subprocess.run([str(BEAMCTL), "db", str(FIXTURES / "site.substitutions")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "TPL:Stage-PosActRB" in records(r.stdout)


def test_a_bad_instance_is_named_with_its_place_in_the_substitution_file(tmp_path):
    require_binary()
    for f in FIXTURES.iterdir():
        shutil.copy(f, tmp_path / f.name)
    subs = tmp_path / "site.substitutions"
    subs.write_text(subs.read_text().replace('file axis_extra.template {', 'file nothere.template {'))
    r = subprocess.run([str(BEAMCTL), "db", str(subs)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1
    assert f"{subs}:9:" in r.stderr and "instance of nothere.template" in r.stderr, r.stderr


def test_the_set_serves_in_run_and_its_asyn_addresses_reach_the_axes(tmp_path, prefix):
    shutil.copytree(FIXTURES, tmp_path / "templates")
    shutil.copy(JACK, tmp_path / "jack.yaml")
    with running_ioc(tmp_path, prefix, IOC):
        # the alias reads the record; the asyn address reads the axis's actual position
        assert wait_for(lambda: ca.get(connect(prefix + "Stage-Position")) ==
                        ca.get(connect(prefix + "Stage-PosAct")), timeout=5)
        assert epics.caget(prefix + "Rot-PosActRB.EGU") == "deg"
        assert epics.caget(prefix + "Stage-Park") == 2.5
        assert epics.caget(prefix + "Stage:PARK.DRVH") == 10
        assert epics.caget(prefix + "Spare-PosActRB.PREC") == 5
        # enabling axis 1 (its EnaCmd) shows in the asynMask bit record of the status word
        assert epics.caget(prefix + "Stage-EnabledRB") == 0
        ca.put(connect(prefix + "Stage-EnaCmd"), 1, wait=True)
        assert wait_for(lambda: ca.get(connect(prefix + "Stage-EnabledRB")) == 1, timeout=10)
        assert ca.get(connect(prefix + "Spare-EnabledRB")) == 1  # the same axis, AXIS_NO 1
        assert ca.get(connect(prefix + "Rot-EnabledRB")) == 0
