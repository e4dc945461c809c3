"""`beamctl softioc` with EPICS softIoc's command line: -m/-d/-x/-a in command-line order,
positional .db files and st.cmd startup scripts (epicsEnvSet, dbLoadTemplate with a substitution
file, dbpf after iocInit), the exit record, and script errors that name file:line and stop the
IOC before it serves."""

import os
import re
import subprocess
import time

import pytest

from conftest import (BEAMCTL, IocServer, acquire_port, connect, forget_pvs, release_port,
                      require_binary, wait_for)

import epics
from epics import ca

DB = """record(ao, "$(P)sp") { field(PREC, "2") field(DESC, "$(D=dflt)") }
record(bo, "$(P)sw") { field(ZNAM, "Off") field(ONAM, "On") }
"""

TEMPLATE = """record(ao, "$(SYS)$(AX)pos") {
    field(DESC, "$(DESC=axis)")
    field(EGU, "$(EGU=mm)")
    field(PREC, "3")
}
"""

SUBSTITUTIONS = """# axes of the test IOC
global { EGU = mm }
file "db/axis.template" {
    pattern { AX, DESC }
    { m1:, "first axis" }
    { m2:, second }
}
file db/axis.template {
    { AX=m3:, EGU=deg }
}
"""


class CliServer(IocServer):
    """`beamctl softioc ARGS...` on a pool port, in `workdir`."""

    def __init__(self, workdir, args, port, extra_env=None, name="cli"):
        super().__init__(workdir, [], port, extra_env=extra_env, name=name)
        self.args = [str(a) for a in args]

    def argv(self):
        return [str(BEAMCTL), "softioc", *self.args]


@pytest.fixture
def cli(tmp_path, prefix):
    """Factory: cli(args) starts `beamctl softioc args` (ready) on a pool port; stops them all."""
    servers, ports = [], []

    def start(args, extra_env=None, port=None):
        if port is None:
            port = acquire_port()
            ports.append(port)
        srv = CliServer(tmp_path, args, port, extra_env=extra_env, name=f"cli{len(servers) + 1}")
        servers.append(srv)
        return srv.start()

    try:
        yield start
    finally:
        forget_pvs(prefix)
        for s in servers:
            s.kill()
        for p in ports:
            release_port(p)


def run_to_exit(args, cwd, port, timeout=20, env_extra=None):
    """Runs `beamctl softioc args` that is expected to fail before serving; returns (rc, out, err)."""
    require_binary()
    env = dict(os.environ, EPICS_CAS_SERVER_PORT=str(port), EPICS_CAS_INTF_ADDR_LIST="127.0.0.1")
    env.update(env_extra or {})
    r = subprocess.run([str(BEAMCTL), "softioc", *map(str, args)], cwd=str(cwd), env=env,
                       capture_output=True, text=True, timeout=timeout)
    return r.returncode, r.stdout, r.stderr


def test_m_applies_to_the_d_after_it_and_replaces_the_one_before(cli, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    cli(["-m", f"P={prefix}a:,D=first", "-d", "x.db",
         "-m", f"P={prefix}b:", "-d", "x.db"])
    assert epics.caget(prefix + "a:sp.DESC", timeout=5) == "first"
    # the second -m replaced the first one: D is back to its default
    assert epics.caget(prefix + "b:sp.DESC", timeout=5) == "dflt"
    assert epics.caput(prefix + "b:sw", "On", wait=True, timeout=5) == 1
    assert epics.caget(prefix + "b:sw", as_string=True) == "On"


def test_positional_db_files_take_every_m_as_before(cli, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    srv = cli(["-m", f"P={prefix}", "x.db", "-m", "D=later"])
    assert epics.caget(prefix + "sp.DESC", timeout=5) == "later"
    assert re.match(r"ready: CA on 127\.0\.0\.1:\d+, 2 PVs$", srv.ready_line), srv.ready_line


def test_x_exit_record_stops_the_ioc_cleanly(cli, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    ioc = prefix + "ioc"
    srv = cli(["-m", f"P={prefix}", "-d", "x.db", "-x", ioc])
    version = epics.caget(ioc + ":BaseVersion", timeout=5)
    assert version.startswith("beamctl "), version
    assert srv.alive()
    assert epics.caput(ioc + ":exit", 1, wait=True, timeout=5) == 1
    srv.proc.wait(timeout=10)
    assert srv.proc.returncode == 0, srv.stderr()


def test_st_cmd_with_env_template_and_dbpf_after_iocinit(cli, tmp_path, prefix):
    port = acquire_port()      # the port the script chooses
    decoy = acquire_port()     # the port of the environment, which the script overrides
    try:
        (tmp_path / "db").mkdir()
        (tmp_path / "db" / "axis.template").write_text(TEMPLATE)
        (tmp_path / "ioc.substitutions").write_text(SUBSTITUTIONS)
        (tmp_path / "st.cmd").write_text(f"""#!../../bin/linux-x86_64/softIoc
# the usual preamble, accepted and ignored
dbLoadDatabase "dbd/softIoc.dbd"
softIoc_registerRecordDeviceDriver(pdbbase)

epicsEnvSet("SYS", "{prefix}")
epicsEnvSet EPICS_CAS_SERVER_PORT {port}
dbLoadTemplate("ioc.substitutions", "SYS=$(SYS)")
iocInit
dbpf $(SYS)m1:pos 12.5
dbpf ${{SYS}}m3:pos.DESC "rotation stage"
""")
        srv = cli(["st.cmd"], extra_env={"EPICS_CAS_SERVER_PORT": str(decoy)}, port=decoy)
        # EPICS_CAS_SERVER_PORT set by the script before iocInit is the one served
        assert srv.ready_line.startswith(f"ready: CA on 127.0.0.1:{port}, 3 PVs"), srv.ready_line
        assert epics.caget(prefix + "m1:pos", timeout=5) == 12.5
        assert epics.caget(prefix + "m1:pos.DESC") == "first axis"
        assert epics.caget(prefix + "m2:pos.DESC") == "second"
        assert epics.caget(prefix + "m3:pos.EGU") == "deg"
        assert epics.caget(prefix + "m1:pos.EGU") == "mm"
        assert epics.caget(prefix + "m3:pos.DESC") == "rotation stage"
        # dbpf processed the record (never-processed records are UDF/INVALID)
        assert epics.caget(prefix + "m1:pos.SEVR", as_string=True) == "NO_ALARM"
        assert epics.caget(prefix + "m2:pos.SEVR", as_string=True) == "INVALID"
        # the script is echoed as iocsh does, dbpf prints the value as EPICS does
        out = "\n".join(srv.stdout_lines)
        assert f"dbpf {prefix}m1:pos 12.5" in srv.stdout_lines, out
        assert any(re.fullmatch(r"DBF_DOUBLE:\s+12\.5\s*", l) for l in srv.stdout_lines), out
        assert "st.cmd:3: note: dbLoadDatabase ignored" in srv.stderr()
    finally:
        release_port(port)
        release_port(decoy)


def test_bad_script_line_names_file_and_line_and_exits_before_serving(tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    (tmp_path / "st.cmd").write_text(f"""epicsEnvSet P {prefix}
dbLoadRecords("x.db", "P=$(P)")

dbLoadRecrods("x.db", "P=$(P)again:")
iocInit
""")
    port = acquire_port()
    try:
        rc, out, err = run_to_exit(["st.cmd"], tmp_path, port)
    finally:
        release_port(port)
    assert rc != 0
    assert "ready:" not in out
    assert "st.cmd:4: unknown command 'dbLoadRecrods' (did you mean 'dbLoadRecords'?)" in err, err
    assert "iocInit" not in out  # the script stopped at the bad line


@pytest.mark.parametrize("script, expected", [
    ("iocInit\ndbpf nosuch:pv 1\n", "st.cmd:2: dbpf: PV 'nosuch:pv' not found"),
    ("dbpf x 1\n", "st.cmd:1: dbpf only works after iocInit"),
    ("echo \"unbalanced\n", "st.cmd:1: Unbalanced quote."),
    ("dbLoadRecords(\"$(NOT_SET_ANYWHERE)x.db\")\n", "st.cmd:1:16: undefined macro 'NOT_SET_ANYWHERE'"),
    ("dbLoadTemplate bad.substitutions\n",
     "bad.substitutions:2:8: expected '=' after AX, found 'm1'\n  loaded by st.cmd:1 (dbLoadTemplate)"),
    ("dbLoadRecords bad.db\n", "bad.db:2:11: "),
])
def test_script_errors(tmp_path, script, expected):
    (tmp_path / "bad.substitutions").write_text("file x.db {\n  { AX m1 }\n}\n")
    (tmp_path / "bad.db").write_text('record(ao, "r") {\n    field(NOPE, "1")\n}\n')
    (tmp_path / "st.cmd").write_text(script)
    port = acquire_port()
    try:
        rc, out, err = run_to_exit(["st.cmd"], tmp_path, port)
    finally:
        release_port(port)
    assert rc != 0 and "ready:" not in out
    assert expected in err, err


def test_nothing_to_do_is_a_usage_error(tmp_path):
    port = acquire_port()
    try:
        rc, out, err = run_to_exit(["-S", "-s", "-D", "softIoc.dbd"], tmp_path, port)
    finally:
        release_port(port)
    assert rc == 2
    assert "beamctl softioc: nothing to do" in err, err


def test_acf_takes_the_macros_before_it(cli, tmp_path, prefix):
    (tmp_path / "x.db").write_text('record(ao, "$(P)ro") { field(ASG, "$(G)") }\n'
                                   'record(ao, "$(P)rw") { }\n')
    (tmp_path / "x.acf").write_text("ASG(DEFAULT) { RULE(1, READ) RULE(1, WRITE) }\n"
                                    "ASG($(G)) { RULE(1, READ) }\n")
    cli(["-m", f"P={prefix},G=LOCKED", "-a", "x.acf", "-d", "x.db"])
    ro, rw = connect(prefix + "ro"), connect(prefix + "rw")
    assert (ca.read_access(ro), ca.write_access(ro)) == (True, False)
    assert (ca.read_access(rw), ca.write_access(rw)) == (True, True)
