"""The beamctl command line: unknown subcommands and options named (exit code 2, the closest
known word suggested, where help is), macro overrides for the IOC file (`run`/`check`/`db -m`),
`--ca-port`, and `plc check --ioc` compiling with the IOC's PLC include directories."""

import subprocess

import pytest
from epics import ca

from conftest import (BEAMCTL, REPO_ROOT, RunServer, acquire_port, connect, forget_pvs, release_port,
                      require_binary, wait_for)

SUBCOMMANDS = ["softioc", "db", "run", "scanner", "check", "signals", "plan", "plc", "axis", "rcp-sim", "sim", "shell",
               "ca-repeater", "esi"]


def beamctl(*args, cwd=None):
    require_binary()
    return subprocess.run([str(BEAMCTL), *map(str, args)], capture_output=True, text=True, timeout=60,
                          cwd=cwd or REPO_ROOT)


def usage_error(*args):
    """Runs beamctl with a bad command line; asserts it is a usage error (exit 2, no crash, nothing
    on stdout) and returns its stderr."""
    r = beamctl(*args)
    assert r.returncode == 2, (args, r.returncode, r.stderr)
    assert r.stdout == "", (args, r.stdout)
    for crash in ("terminate called", "Sanitizer", "Segmentation", "Aborted"):
        assert crash not in r.stderr
    return r.stderr


# ---------------------------------------------------------------------------------------------
# Unknown words
# ---------------------------------------------------------------------------------------------
def test_unknown_subcommand_is_named_with_the_list_of_subcommands():
    err = usage_error("frobnicate")
    first = err.splitlines()[0]
    assert first.startswith("beamctl: unknown subcommand 'frobnicate'; subcommands: "), err
    assert first.split("subcommands: ")[1].split() == SUBCOMMANDS
    assert "did you mean" not in err  # nothing is close to 'frobnicate'
    assert "Run 'beamctl --help'" in err


def test_mistyped_subcommand_gets_the_closest_one():
    err = usage_error("chek", "examples/demo/ioc.yaml")
    assert err.splitlines()[0].startswith("beamctl: unknown subcommand 'chek' (did you mean 'check'?); "), err
    assert "examples/demo/ioc.yaml" not in err  # the words after it were meant for it


def test_unknown_option_of_a_subcommand_is_named():
    err = usage_error("run", "--bogus", "x.yaml")
    assert err.splitlines()[0] == "beamctl run: unknown option '--bogus'", err
    assert "Run 'beamctl run --help' for its options." in err


def test_mistyped_option_gets_the_closest_one():
    err = usage_error("run", "--ca-prot=5070", "examples/demo/ioc.yaml")
    assert "beamctl run: unknown option '--ca-prot' (did you mean '--ca-port'?)" in err, err


def test_unknown_option_and_missing_argument_are_both_reported():
    err = usage_error("db", "--bogus")
    assert "beamctl db: unknown option '--bogus'" in err, err
    assert "beamctl db: files is required" in err, err


def test_unknown_option_before_the_subcommand_belongs_to_beamctl():
    err = usage_error("--bogus", "check", "examples/demo/ioc.yaml")
    assert err.splitlines()[0] == "beamctl: unknown option '--bogus'", err
    assert "Run 'beamctl --help'" in err


def test_unknown_nested_subcommand_and_surplus_argument():
    err = usage_error("plc", "frob")
    assert "beamctl plc: unknown subcommand 'frob'; subcommands: check" in err, err
    err = usage_error("check", "a.yaml", "b.yaml")
    assert "beamctl check: unexpected argument 'b.yaml'" in err, err
    err = usage_error("esi", "imprt", "x.xml")
    assert "beamctl esi: unknown subcommand 'imprt' (did you mean 'import'?); subcommands: import" in err, err
    err = usage_error("esi", "import")
    assert "beamctl esi import: files is required" in err, err


def test_missing_subcommand_lists_them():
    err = usage_error()
    assert err.splitlines()[0] == "beamctl: a subcommand is required: " + " ".join(SUBCOMMANDS), err


def test_bad_option_value_names_the_option():
    err = usage_error("run", "--ca-port", "70000", "examples/demo/ioc.yaml")
    assert err.startswith("beamctl run: --ca-port: "), err


def test_help_still_works():
    r = beamctl("run", "--help")
    assert r.returncode == 0, r.stderr
    for opt in ("-m,--macros", "--ca-port", "file"):
        assert opt in r.stdout, r.stdout
    r = beamctl("--version")
    assert r.returncode == 0 and r.stdout.startswith("beamctl "), r


# ---------------------------------------------------------------------------------------------
# Macros in the IOC file, --ca-port
# ---------------------------------------------------------------------------------------------
IOC = """\
# $(UNDEFINED) in a comment, and ${NOT_GIVEN} below, stay as they are
ioc: {name: "$(NAME)", prefix: "${P}"}
engine: {rate_hz: $(RATE=500)}
buses:
  - id: 0
    link: {type: sim}
    slaves:
      - {position: 0, type: EK1100}
      - {position: $(POS), type: EL1008}
"""


def write_ioc(tmp_path, text=IOC):
    path = tmp_path / "ioc.yaml"
    path.write_text(text)
    return path


def test_check_and_db_expand_macros_from_the_command_line(tmp_path):
    ioc = write_ioc(tmp_path)
    r = beamctl("check", "-m", "NAME=MAC,P=MAC:", "-m", "POS=1", ioc)
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"{ioc}: OK (97 PVs, 1 bus(es))\n", r.stdout
    r = beamctl("db", "-m", "NAME=MAC,P=MAC:,POS=1", ioc)
    assert r.returncode == 0, r.stderr
    assert 'record(bi, "MAC:m0s001-BI01")' in r.stdout, r.stdout[:500]
    # a later -m replaces an earlier value; the default of $(RATE=500) gives way to a value
    r = beamctl("db", "-m", "NAME=MAC,P=MAC:,POS=1", "-m", "P=OTHER:,RATE=250", ioc)
    assert r.returncode == 0, r.stderr
    assert 'record(bi, "OTHER:m0s001-BI01")' in r.stdout and "MAC:m0" not in r.stdout


def test_a_macro_without_value_is_an_error_that_shows_it(tmp_path):
    ioc = write_ioc(tmp_path)
    r = beamctl("check", "-m", "P=MAC:,POS=1", ioc)  # NAME not given, no default
    assert r.returncode == 1
    assert f"{ioc}:2:" in r.stderr and "'$(NAME)'" in r.stderr, r.stderr
    r = beamctl("check", "-m", "NAME", ioc)
    assert r.returncode == 1
    assert r.stderr.startswith("-m:1:"), r.stderr


def test_a_macro_error_names_the_place_in_the_ioc_file(tmp_path):
    ioc = write_ioc(tmp_path, IOC.replace("$(RATE=500)", "$(RATE=$(RATE))"))
    r = beamctl("check", "-m", "NAME=MAC,P=MAC:,POS=1", ioc)
    assert r.returncode == 1
    assert r.stderr.startswith(f"{ioc}:3:"), r.stderr


def run_server(tmp_path, config, port, args, extra_env=None):
    class Server(RunServer):
        def argv(self):
            return [str(BEAMCTL), "run", *map(str, args), self.config]

    srv = Server(tmp_path, config, port)
    srv.extra_env = dict(extra_env or {})
    return srv


def test_run_with_macros_and_ca_port_over_the_file_and_the_environment(tmp_path, prefix):
    ports = [acquire_port() for _ in range(3)]
    served, env_port, file_port = ports
    ioc = write_ioc(tmp_path, IOC + f"ca: {{port: {file_port}}}\n")
    srv = run_server(tmp_path, ioc, served,
                     ["-m", f"NAME={prefix.rstrip(':')},P={prefix},POS=1", "--ca-port", served],
                     extra_env={"EPICS_CAS_SERVER_PORT": str(env_port)})
    try:
        srv.start()
        assert srv.ready_line.startswith(f"ready: CA on 127.0.0.1:{served}, "), srv.ready_line
        assert wait_for(lambda: ca.get(connect(prefix + "m0-Stat-OK")) == 1)
        assert ca.get(connect(prefix + "m0-SlvCntr")) == 2
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        for p in ports:
            release_port(p)


# ---------------------------------------------------------------------------------------------
# plc check --ioc
# ---------------------------------------------------------------------------------------------
def test_plc_check_with_ioc_uses_its_include_directories(tmp_path):
    # examples/demo/plc/slit.plc includes slit_plane.plc_inc from ../plc_lib, the demo's
    # `plcs: include:`; the file is compiled against the demo's axes
    slit = REPO_ROOT / "examples" / "demo" / "plc" / "slit.plc"
    r = beamctl("plc", "check", slit)
    assert r.returncode == 1 and "slit_plane.plc_inc" in r.stderr, (r.stdout, r.stderr)
    r = beamctl("plc", "check", "--ioc", REPO_ROOT / "examples" / "demo" / "ioc.yaml", slit)
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"{slit}: OK\n"


def test_plc_check_with_ioc_include_directories_for_another_file(tmp_path):
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "helper.plc_inc").write_text("static.count := static.count + 1;\n")
    (tmp_path / "main.plc").write_text('include "helper.plc_inc"\n')
    (tmp_path / "ioc.yaml").write_text(
        "ioc: {name: PLCI}\nplcs:\n  - {id: 0, file: main.plc, include: [lib]}\n")
    other = tmp_path / "other.plc"
    other.write_text('include "helper.plc_inc"\nstatic.x := static.count * 2;\n')
    r = beamctl("plc", "check", other)
    assert r.returncode == 1 and "helper.plc_inc" in r.stderr, r.stderr
    r = beamctl("plc", "check", "--ioc", tmp_path / "ioc.yaml", other)
    assert r.returncode == 0, r.stderr
    # -I comes first, then the IOC's directories
    (tmp_path / "first").mkdir()
    (tmp_path / "first" / "helper.plc_inc").write_text("static.count := nosuchthing;\n")
    r = beamctl("plc", "check", "-I", tmp_path / "first", "--ioc", tmp_path / "ioc.yaml", other)
    assert r.returncode == 1 and "nosuchthing" in r.stderr, r.stderr


def test_scanner_usage_and_errors(tmp_path):
    r = beamctl("scanner")
    assert r.returncode == 1 and "the scanner configuration file is required" in r.stderr, r.stderr
    bad = tmp_path / "s.yaml"
    bad.write_text("scanner: {socket: s.sock}\nbuses:\n  - {id: 0, slaves: [{position: 0, type: EK1100}]}\n")
    r = beamctl("scanner", bad)
    assert r.returncode == 1, r.stderr
    assert f"{bad}:3:22: buses[0].slaves[0]: missing required key 'name'" in r.stderr, r.stderr
    r = beamctl("scanner", "status", tmp_path / "nothing.sock")
    assert r.returncode == 1, r.stderr
    assert "nothing.sock: No such file or directory (is `beamctl scanner` running?)" in r.stderr, r.stderr
    err = usage_error("scanner", "status")
    assert "socket" in err, err
