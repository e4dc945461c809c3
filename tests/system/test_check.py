"""`beamctl check` reports every error at once, each with file:line:col: those of the IOC file, of
each file it names (an axis file, a PLC file, a .db file), and a file that cannot be read at the
place of the IOC file that names it; an unknown slave type comes with the catalog's close matches."""

import re
import shutil
import subprocess
from pathlib import Path

from conftest import BEAMCTL, acquire_port, release_port, require_binary

DATA = Path(__file__).parent / "data" / "axes"

IOC = """ioc: {name: CHK}
engine: {rate_hz: 0, cpus: 1}
buses:
  - id: 0
    link: {type: sim, plant: noplant.yaml}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL1008}
      - {position: 2, type: EL7041}
      - {position: 3, type: EL7014}
axes:
  - {file: stepper.yaml, macros: {AX_NAME: X, DRV_SLAVE: 2}}
  - {file: axes/nothere.yaml, macros: {AX_NAME: Y}}
plcs:
  - {file: main.plc}
db:
  - {file: extra.db}
"""

PLC = "static.a := 1;\nstatic.b := nosuch + 1;\n"

DB = 'record(ai, "CHK:a") {\n  field(VAL 1)\n}\nrecord(ai, "CHK:b") {\n  field(EGU, @)\n}\n'


def where(path, needle):
    """'path:line:col' of the first `needle` in the file (columns count from 1)."""
    for n, line in enumerate(Path(path).read_text().splitlines(), start=1):
        col = line.find(needle)
        if col >= 0:
            return f"{path}:{n}:{col + 1}"
    raise AssertionError(f"{needle!r} is not in {path}")


def check(cfg):
    require_binary()
    return subprocess.run([str(BEAMCTL), "check", str(cfg)], capture_output=True, text=True,
                          timeout=60)


def test_every_error_of_the_ioc_file_and_the_files_it_names(tmp_path):
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(IOC)
    axis = tmp_path / "stepper.yaml"
    axis.write_text((DATA / "stepper.yaml").read_text()
                    .replace("velocity: 5", "velocity: -5")
                    .replace("Kp: 10", "Kpp: 10")
                    .replace("bits: 16", "bits: 99"))
    plc = tmp_path / "main.plc"
    plc.write_text(PLC)
    db = tmp_path / "extra.db"
    db.write_text(DB)

    r = check(ioc)
    assert r.returncode == 1, r.stdout + r.stderr
    expected = [
        # the IOC file
        f"{where(ioc, '0, cpus')}: engine.rate_hz should be from 1 to 20000, got 0",
        f"{where(ioc, 'cpus')}: unknown key 'cpus' in engine (did you mean 'cpu'?)",
        # files that cannot be read, at the line of the IOC file that names them
        f"{where(ioc, 'noplant.yaml')}: buses[0].link.plant: {tmp_path}/noplant.yaml: "
        "No such file or directory",
        f"{where(ioc, 'axes/nothere.yaml')}: axes[1].file: {tmp_path}/axes/nothere.yaml: "
        "No such file or directory",
        # an unknown slave type, with the close matches of the catalog
        f"{where(ioc, 'EL7014')}: buses[0] position 3: unknown device type 'EL7014'; "
        "close matches in the catalog: EL7041",
        # the axis file
        f"{where(axis, '-5')}: trajectory.axis.velocity should be > 0, got -5",
        f"{where(axis, '99')}: encoder.bits should be from 0 to 64, got 99",
        # the PLC file
        f"{where(plc, 'nosuch')}: unknown name 'nosuch'",
        # the .db file: both errors, the parser goes on at the next record
        f"{where(db, '1)')}: expected ',' after field name 'VAL', found '1'",
        f"{where(db, '@')}: invalid '@'",
    ]
    # unknown keys of an ECMC axis file are warnings (ECMC's loader drops them), with the hint
    assert f"warning: {where(axis, 'Kpp')}: unknown key 'Kpp' in controller (did you mean 'Kp'?): " \
           "ignored, as ECMC does" in r.stderr, r.stderr
    missing = [e for e in expected if e not in r.stderr]
    assert not missing, "missing:\n" + "\n".join(missing) + "\n\nstderr:\n" + r.stderr
    errors = [line for line in r.stderr.splitlines() if re.match(r"^/\S+:\d+:\d+: ", line)]
    assert len(errors) == len(expected), r.stderr
    assert r.stderr.rstrip().endswith(f"{ioc}: {len(expected)} errors"), r.stderr
    assert "OK" not in r.stdout


def test_a_correct_ioc_is_ok_and_errors_between_files_come_once_each_file_is_right(tmp_path):
    shutil.copy(DATA / "plant.yaml", tmp_path / "plant.yaml")
    shutil.copy(DATA / "stepper.yaml", tmp_path / "stepper.yaml")
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(IOC.replace("rate_hz: 0, cpus: 1", "rate_hz: 1000")
                   .replace("noplant.yaml", "plant.yaml")
                   .replace("      - {position: 3, type: EL7014}\n", "")
                   .replace("  - {file: axes/nothere.yaml, macros: {AX_NAME: Y}}\n", "")
                   .replace("plcs:\n  - {file: main.plc}\ndb:\n  - {file: extra.db}\n", ""))
    r = check(ioc)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"{ioc}: OK ("), r.stdout
    # a link to an entry the bus does not have: known only when the IOC is built
    axis = tmp_path / "stepper.yaml"
    axis.write_text(axis.read_text().replace("positionActual01", "positionActual09"))
    r = check(ioc)
    assert r.returncode == 1
    assert f"{where(axis, 'ec0.s$(DRV_SLAVE).positionActual09')}: no signal " \
           "'ec0.s2.positionActual09'" in r.stderr, r.stderr


def test_an_ioc_file_that_cannot_be_read(tmp_path):
    r = check(tmp_path / "none.yaml")
    assert r.returncode == 1
    assert f"{tmp_path}/none.yaml: cannot open: No such file or directory" in r.stderr, r.stderr


JACK = Path(__file__).parents[2] / "examples" / "demo" / "axes" / "jack.yaml"

PHASES = """ioc: {name: PH}
engine: {rate_hz: 1000, priorty: 50}
buses:
  - id: 0
    link: {type: sim}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL7041}
      - {position: 2, type: EL7041}
axes:
  - {file: jack.yaml, macros: {AX_ID: 1, AX_NAME: J1, DRV_SLAVE: 1}}
  - {file: jack.yaml, macros: {AX_ID: 2, AX_NAME: J2, DRV_SLAVE: 5}}
  - {file: jack.yaml, macros: {AX_ID: 3, AX_NAME: J3, DRV_SLAVE: 2}}
kinematics:
  - name: pair
    virtual: [3]
    real: [1, 2]
    inverse: |
      ax1 := ax3 +;
db:
  - {file: extra.db}
"""


def test_mistakes_of_several_files_come_in_one_run_with_their_chain_and_run_reports_the_same(tmp_path):
    """The four kinds of mistake of issue 41 in one file set: a key typo, a bad signal in a shared
    axis file (named with the ioc.yaml entry and the macros that passed it), a kinematics error
    and two .db errors: `check` reports them all in one run, `run` the same set."""
    shutil.copy(JACK, tmp_path / "jack.yaml")
    ioc = tmp_path / "ioc.yaml"
    ioc.write_text(PHASES)
    (tmp_path / "extra.db").write_text(DB)
    r = check(ioc)
    assert r.returncode == 1, r.stdout + r.stderr
    errors = [line for line in r.stderr.splitlines() if re.match(r"^/\S+:\d+:\d+: ", line)]
    text = "\n".join(errors)
    assert f"{where(ioc, 'priorty')}: unknown key 'priorty' in engine (did you mean 'priority'?)" in text, text
    # J2's bus signals (setpoint, control, status, position, ...), each after the entry that passed
    # DRV_SLAVE=5, none of J1's or J3's
    chain = f"{where(ioc, '{file: jack.yaml, macros: {AX_ID: 2')}: axes[1] (jack.yaml with AX_ID=2, AX_NAME=J2, DRV_SLAVE=5): "
    bad = [e for e in errors if "no signal 'ec0.s5." in e]
    assert len(bad) >= 4 and any("positionActual01" in e for e in bad), text
    assert all(e.startswith(chain + f"{tmp_path}/jack.yaml:") for e in bad), text
    assert not any("ec0.s1." in e or "ec0.s2." in e for e in errors), text
    # the inline inverse's error at its line and column of ioc.yaml (the ';' of `ax1 := ax3 +;`)
    assert f"{where(ioc, ';')}: kinematics 'pair' inverse: expected a value, found ';'" in text, text
    db = tmp_path / "extra.db"
    assert f"{where(db, '1)')}: expected ',' after field name 'VAL', found '1'" in text, text
    assert f"{where(db, '@')}: invalid '@'" in text, text
    assert r.stderr.rstrip().endswith(f"{ioc}: {len(errors)} errors"), r.stderr
    # `run` refuses to start with the same set
    port = acquire_port()
    try:
        run = subprocess.run([str(BEAMCTL), "run", "--ca-port", str(port), "--shell-socket", "none", str(ioc)],
                             capture_output=True, text=True, timeout=60)
    finally:
        release_port(port)
    assert run.returncode == 1, run.stdout + run.stderr
    run_errors = [line for line in run.stderr.splitlines() if re.match(r"^/\S+:\d+:\d+: ", line)]
    assert run_errors == errors, "\n".join(run_errors) + "\n---\n" + text
    assert "ready:" not in run.stdout


# PHASES's IOC with the second axis file missing, two kinematics groups and PLC code naming it
FOLLOW_ON = (PHASES.replace("priorty: 50", "priority: 50")
             .replace("{file: jack.yaml, macros: {AX_ID: 2, AX_NAME: J2, DRV_SLAVE: 5}}",
                      "{file: nothere.yaml, macros: {AX_ID: 2, AX_NAME: J2, DRV_SLAVE: 2}}")
             .replace("    real: [1, 2]\n    inverse: |\n      ax1 := ax3 +;\n",
                      "    real: [1]\n    inverse: |\n      ax1 := ax3 +;\n      ax1 := ax9 * 2;\n      ax1 := (ax3;\n"
                      "  - name: other\n    virtual: [2]\n    real: [1]\n    inverse: |\n      ax1 := ax2;\n")
             .replace("db:\n  - {file: extra.db}\n", "plcs:\n  - {file: main.plc}\n"))


def test_an_axis_that_does_not_load_is_named_once_and_its_follow_ons_say_so(tmp_path):
    """A missing axis file comes once (at the ioc.yaml line that names it); PLC code and a
    kinematics group naming that axis say that it did not load; an inverse with a bracket that is
    never closed still reports the errors of the statements before it."""
    shutil.copy(JACK, tmp_path / "jack.yaml")
    ioc = tmp_path / "ioc.yaml"
    assert "nothere.yaml" in FOLLOW_ON and "name: other" in FOLLOW_ON and "main.plc" in FOLLOW_ON
    ioc.write_text(FOLLOW_ON)
    (tmp_path / "main.plc").write_text("ax2.drv.enable := 1;\n")
    r = check(ioc)
    assert r.returncode == 1, r.stdout + r.stderr
    errors = [line for line in r.stderr.splitlines() if re.match(r"^/\S+:\d+:\d+: ", line)]
    text = "\n".join(errors)
    assert sum("nothere.yaml: No such file" in e or "nothere.yaml: cannot open" in e for e in errors) == 1, text
    note = f"[axes[1] ({tmp_path}/nothere.yaml) did not load: see its errors]"
    plc = [e for e in errors if "main.plc" in e]
    assert len(plc) == 1 and "no axis 2" in plc[0] and plc[0].endswith(note), text
    other = [e for e in errors if "kinematics 'other'" in e]
    assert len(other) == 1 and other[0].endswith(f"no axis 2 (virtual) {note}"), text
    pair = [e for e in errors if "kinematics 'pair' inverse:" in e]
    lines = [int(e.split(":")[1]) for e in pair]  # ioc.yaml's lines of the three statements
    first = int(where(ioc, "ax1 := ax3 +;").split(":")[1])
    assert lines == [first, first + 1, first + 2], text
    assert pair[0].startswith(where(ioc, "ax1 := ax3 +;").rsplit(":", 1)[0] + ":"), text
    assert pair[2].endswith("'(' is never closed"), text
    assert r.stderr.rstrip().endswith(f"{ioc}: {len(errors)} errors"), r.stderr
