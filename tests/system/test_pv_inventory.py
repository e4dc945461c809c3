"""The PVs of every example IOC, as `beamctl db ioc.yaml` prints them (every record, its type and
fields), against the inventory committed in tests/fixtures/pv_inventory/. The module redesign of
issue 42 moves code between folders and must not change what any IOC serves: this test is the
proof. A deliberate change of the PVs regenerates the inventory (and shows in review):

    BEAMCTL_UPDATE_PV_INVENTORY=1 /usr/bin/python3 -m pytest -q tests/system/test_pv_inventory.py
"""

import difflib
import os
import re
import subprocess

import pytest

from conftest import BEAMCTL, REPO_ROOT, require_binary

INVENTORY = REPO_ROOT / "tests" / "fixtures" / "pv_inventory"
# Every example IOC file (a top-level `ioc:`) that loads offline: not examples/scanner/ioc_b.yaml,
# whose slaves only a running `beamctl scanner` names, nor examples/rcp/model.yaml (an RCP model,
# whose `ioc:` is the name of the machine it stands in for).
EXAMPLES = sorted(str(p.relative_to(REPO_ROOT)) for p in REPO_ROOT.glob("examples/*/*.yaml")
                  if re.search(r"(?m)^ioc:", p.read_text()) and p.name not in ("ioc_b.yaml", "model.yaml"))


def inventory_file(example):
    return INVENTORY / (example.replace("examples/", "").replace("/", "_").replace(".yaml", ".db"))


def test_the_examples_are_found():
    assert "examples/demo/ioc.yaml" in EXAMPLES and len(EXAMPLES) >= 12, EXAMPLES


@pytest.mark.parametrize("example", EXAMPLES)
def test_beamctl_db_of_the_example_prints_the_committed_pvs(example):
    require_binary()
    r = subprocess.run([str(BEAMCTL), "db", example], capture_output=True, text=True, timeout=120, cwd=REPO_ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.count("record(") > 10, r.stdout[:2000]
    path = inventory_file(example)
    if os.environ.get("BEAMCTL_UPDATE_PV_INVENTORY") == "1":
        INVENTORY.mkdir(parents=True, exist_ok=True)
        path.write_text(r.stdout)
    assert path.exists(), f"no inventory {path}: run with BEAMCTL_UPDATE_PV_INVENTORY=1 once"
    want = path.read_text()
    if r.stdout != want:
        diff = "".join(list(difflib.unified_diff(want.splitlines(True), r.stdout.splitlines(True),
                                                 str(path), "beamctl db " + example))[:200])
        pytest.fail(f"the PVs of {example} changed:\n{diff}")
