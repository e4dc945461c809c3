"""`beamctl esi import` end to end: vendor ESI XML into a catalog directory, then an IOC that
uses a device only that catalog has (BEAMCTL_CATALOG) checks and lists its signals; without it
the IOC's error names the device and says how to import it. A bad file writes nothing, and a
file the import did not write is replaced only with --force (docs/esi.md)."""

import os
import re
import subprocess

from conftest import BEAMCTL, REPO_ROOT, require_binary

FIXTURES = REPO_ROOT / "tests" / "fixtures" / "esi"
NEW = FIXTURES / "new" / "EL1018.xml"  # not in catalog/, two revisions, vendor entry names

IOC = """\
ioc: {name: NEW, prefix: "NEW:"}
buses:
  - id: 0
    link: {type: sim}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL1018}
"""


def beamctl(*args, catalog=None):
    require_binary()
    env = dict(os.environ)
    env.pop("BEAMCTL_CATALOG", None)
    if catalog is not None:
        env["BEAMCTL_CATALOG"] = str(catalog)
    return subprocess.run([str(BEAMCTL), *map(str, args)], capture_output=True, text=True, timeout=60,
                          cwd=REPO_ROOT, env=env)


def test_imported_device_is_usable_through_beamctl_catalog(tmp_path):
    cat = tmp_path / "catalog"  # created by the import
    r = beamctl("esi", "import", NEW, FIXTURES / "EK1100.xml", "--out", cat)
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    assert r.stdout.splitlines() == [
        f"wrote {cat}/EL1018_rev0x00100000.yaml (EL1018 revision 0x00100000)",
        f"wrote {cat}/EL1018_rev0x00120000.yaml (EL1018 revision 0x00120000)",
        f"wrote {cat}/EK1100.yaml (EK1100 revision 0x00120000)",
    ]
    assert sorted(p.name for p in cat.iterdir()) == ["EK1100.yaml", "EL1018_rev0x00100000.yaml",
                                                     "EL1018_rev0x00120000.yaml"]
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(IOC)

    r = beamctl("check", ioc, catalog=cat)
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"{ioc}: OK (97 PVs, 1 bus(es))\n", r.stdout
    # the vendor's repeated entry names become <Pdo>_<Entry>; the highest revision is used
    r = beamctl("signals", ioc, "ec0.s1.Ch*", catalog=cat)
    assert r.returncode == 0, r.stderr
    names = [line.split()[0] for line in r.stdout.splitlines()[1:]]
    assert names == [f"ec0.s1.Channel{k}_Input" for k in range(1, 9)], r.stdout
    assert "NEW:m0s001-Channel1_Input" in r.stdout

    # the catalog of the source tree lacks it: the error says how to import it
    r = beamctl("check", ioc)
    assert r.returncode == 1
    assert re.search(rf"^{re.escape(str(ioc))}:7:\d+: buses\[0\] position 1: unknown device type 'EL1018'; "
                     r"close matches in the catalog: EL1008.*; to add a device, import its vendor's ESI file: "
                     r"beamctl esi import VENDOR\.xml --out \S*catalog \(BEAMCTL_CATALOG selects the catalog "
                     r"directory; docs/esi\.md\)$", r.stderr, re.M), r.stderr


def test_catalog_terminals_import_to_files_that_load_like_the_hand_written_ones(tmp_path):
    cat = tmp_path / "catalog"
    files = sorted(FIXTURES.glob("*.xml"))
    r = beamctl("esi", "import", *files, "--out", cat)
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.splitlines()) == len(files)
    # an IOC with the demo's terminals checks the same against the imported catalog
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(IOC.replace("EL1018", "EL3702, oversampling: 10}\n      - {position: 2, type: EL7041"))
    ok = beamctl("check", ioc)
    assert ok.returncode == 0, ok.stderr
    imported = beamctl("check", ioc, catalog=cat)
    assert imported.returncode == 0, imported.stderr
    assert imported.stdout == ok.stdout
    assert beamctl("db", ioc, catalog=cat).stdout == beamctl("db", ioc).stdout


def test_bad_file_writes_nothing_and_exits_1(tmp_path):
    text = (FIXTURES / "EL5101.xml").read_text().replace("<DataType>USINT</DataType>", "<DataType>USINT8</DataType>", 1)
    bad = tmp_path / "EL5101.xml"
    bad.write_text(text)
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if "USINT8" in ln)
    col = text.splitlines()[line - 1].index("<DataType>USINT8") + 1
    cat = tmp_path / "catalog"
    r = beamctl("esi", "import", bad, FIXTURES / "EL2008.xml", "--out", cat)
    assert r.returncode == 1
    assert r.stderr.splitlines() == [f"{bad}:{line}:{col}: DataType: unknown DataType 'USINT8' (BOOL/BIT, BIT2-BIT8, "
                                     "SINT/INT/DINT/LINT, USINT/UINT/UDINT/ULINT, BYTE/WORD/DWORD, BITARR8-32, REAL/LREAL, "
                                     "INT8-INT64, UINT8-UINT64, REAL32, REAL64)"], r.stderr
    assert sorted(p.name for p in cat.iterdir()) == ["EL2008.yaml"]  # the good file only

    r = beamctl("esi", "import", tmp_path / "nothere.xml", "--out", cat)
    assert r.returncode == 1 and r.stderr == f"{tmp_path}/nothere.xml: cannot open\n", r.stderr
    notxml = tmp_path / "plant.xml"
    notxml.write_text("<?xml version='1.0'?>\n<Plant/>\n")
    r = beamctl("esi", "import", notxml, "--out", cat)
    assert r.returncode == 1 and r.stderr == f"{notxml}:2:1: root element should be <EtherCATInfo>, got <Plant>\n"
    assert sorted(p.name for p in cat.iterdir()) == ["EL2008.yaml"]


def test_hand_written_files_are_replaced_only_with_force(tmp_path):
    cat = tmp_path / "catalog"
    cat.mkdir()
    mine = cat / "EL2008.yaml"
    hand = (REPO_ROOT / "catalog" / "EL2008.yaml").read_text()
    mine.write_text(hand)
    r = beamctl("esi", "import", FIXTURES / "EL2008.xml", "--out", cat)
    assert r.returncode == 1
    assert r.stderr == (f"{FIXTURES}/EL2008.xml:12:7: Device: EL2008 revision 0x00100000 would replace {mine}, "
                        "which beamctl esi import did not write: not replaced (--force replaces it)\n"), r.stderr
    assert mine.read_text() == hand
    r = beamctl("esi", "import", FIXTURES / "EL2008.xml", "--out", cat, "--force")
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"wrote {mine} (EL2008 revision 0x00100000, replaced a file the import did not write)\n"
    assert mine.read_text().startswith("# Generated by beamctl esi import from EL2008.xml:12;")
    # its own file is replaced without asking
    r = beamctl("esi", "import", FIXTURES / "EL2008.xml", "--out", cat)
    assert r.returncode == 0 and r.stdout == f"wrote {mine} (EL2008 revision 0x00100000)\n", r.stderr


def test_without_out_prints_the_entries_and_writes_nothing(tmp_path):
    r = beamctl("esi", "import", FIXTURES / "EL4134.xml")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("# Generated by beamctl esi import from EL4134.xml:12;"), r.stdout
    assert "\ntype: EL4134\n" in r.stdout
    assert r.stderr == "nothing written: give --out DIR (e.g. --out catalog/) to write these entries\n"
    # what it prints is a catalog entry
    cat = tmp_path / "catalog"
    cat.mkdir()
    (cat / "EL4134.yaml").write_text(r.stdout)
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(IOC.replace("EL1018", "EL4134").replace("EK1100", "EL4134"))
    r2 = beamctl("check", ioc, catalog=cat)
    assert r2.returncode == 0, r2.stderr
