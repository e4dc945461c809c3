"""Autosave in `beamctl softioc`, as synApps users know it: info(autosaveFields) fields saved to
.sav files on change and restored at the next start before PINI (with --autosave DIR, and with the
synApps st.cmd commands and a .req file), a clean stop saves at once, a truncated save file is
reported and the IOC starts (with the .savB backup when there is one)."""

import os
import signal
import subprocess
import time

import pytest

from conftest import BEAMCTL, IocServer, acquire_port, forget_pvs, release_port, wait_for

import epics

DB = """record(ao, "$(P)sp") {
    field(PREC, "3")
    field(PINI, "YES")
    field(OUT, "$(P)seen PP")
    info(autosaveFields, "VAL DESC")
}
record(ao, "$(P)seen") { }
record(stringout, "$(P)name") { info(autosaveFields, "VAL") }
record(waveform, "$(P)wf") {
    field(FTVL, "DOUBLE")
    field(NELM, "4")
    info(autosaveFields_pass0, "VAL")
}
record(ao, "$(P)plain") { }
"""


class SoftIoc(IocServer):
    """`beamctl softioc ARGS...` on a pool port, in `workdir`."""

    def __init__(self, workdir, args, port, name):
        super().__init__(workdir, [], port, name=name)
        self.args = [str(a) for a in args]

    def argv(self):
        return [str(BEAMCTL), "softioc", *self.args]


@pytest.fixture
def softioc(tmp_path, prefix):
    """Factory: softioc(args) starts `beamctl softioc args` (ready); every one is killed after."""
    servers = []
    port = acquire_port()

    def start(args):
        srv = SoftIoc(tmp_path, args, port, name=f"as{len(servers) + 1}")
        servers.append(srv)
        return srv.start()

    try:
        yield start
    finally:
        forget_pvs(prefix)
        for s in servers:
            s.kill()
        release_port(port)


def wait_saved(path, text, timeout=30):
    def ok():
        try:
            body = path.read_text()
        except OSError:
            return False
        return text in body and body.endswith("<END>\n")
    assert wait_for(ok, timeout=timeout), f"{path} never held {text!r}: " + (
        path.read_text() if path.exists() else "(missing)")


def test_info_tags_saved_on_change_and_restored_before_pini(softioc, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    args = ["--autosave", "as", "--autosave-period", "1", "-m", f"P={prefix}", "-d", "x.db"]
    srv = softioc(args)
    assert "info_positions.sav: not found" in srv.stderr()
    assert epics.caput(prefix + "sp", 12.345678, wait=True, timeout=5) == 1
    assert epics.caput(prefix + "sp.DESC", "set point", wait=True, timeout=5) == 1
    assert epics.caput(prefix + "name", "hello world", wait=True, timeout=5) == 1
    assert epics.caput(prefix + "wf", [1.5, 2, 3], wait=True, timeout=5) == 1
    assert epics.caput(prefix + "plain", 7, wait=True, timeout=5) == 1
    settings = tmp_path / "as" / "info_settings.sav"
    wait_saved(settings, f"{prefix}name.VAL hello world\n")
    wait_saved(settings, f"{prefix}sp.VAL 12.345678\n")
    wait_saved(tmp_path / "as" / "info_positions.sav", '@array@ { "1.5" "2" "3" }')
    assert settings.read_text().startswith("# save/restore V5.11\tAutomatically generated")
    assert "plain" not in settings.read_text()
    srv.kill()  # no clean stop: what was saved is what comes back
    forget_pvs(prefix)

    srv = softioc(args)
    assert "restored 3 value(s)" in srv.stderr(), srv.stderr()
    assert epics.caget(prefix + "sp", timeout=10) == pytest.approx(12.345678, abs=1e-9)
    assert epics.caget(prefix + "sp.DESC", timeout=5) == "set point"
    # PINI processing ran after the restore: the OUT link carried the restored value.
    assert epics.caget(prefix + "seen", timeout=5) == pytest.approx(12.345678, abs=1e-9)
    assert epics.caget(prefix + "name", timeout=5) == "hello world"
    assert list(epics.caget(prefix + "wf", timeout=5)) == [1.5, 2, 3]
    assert epics.caget(prefix + "plain", timeout=5) == 0


def test_clean_stop_saves_at_once(softioc, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    srv = softioc(["--autosave", "as", "--autosave-period", "3600", "-m", f"P={prefix}", "x.db"])
    settings = tmp_path / "as" / "info_settings.sav"
    wait_saved(settings, f"{prefix}sp.VAL 0\n")  # the first save, at start
    assert epics.caput(prefix + "sp", 4.5, wait=True, timeout=5) == 1
    time.sleep(0.5)
    assert f"{prefix}sp.VAL 4.5\n" not in settings.read_text()  # an hour until the next save
    assert srv.stop() == 0
    assert f"{prefix}sp.VAL 4.5\n" in settings.read_text()
    backup = tmp_path / "as" / "info_settings.savB"
    assert f"{prefix}sp.VAL 0\n" in backup.read_text()  # the file it replaced


def test_synapps_startup_script_with_request_file_and_macros(softioc, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    (tmp_path / "req").mkdir()
    (tmp_path / "req" / "motors.req").write_text("# extra fields\n$(P)plain.VAL\n$(P)plain.EGU\n")
    (tmp_path / "st.cmd").write_text(f"""
epicsEnvSet("P", "{prefix}")
set_savefile_path("{tmp_path}", "autosave")
set_requestfile_path("{tmp_path}", "req")
set_requestfile_path("{tmp_path}")
set_pass0_restoreFile("info_settings.sav")
set_pass1_restoreFile("extra.sav")
save_restoreSet_NumSeqFiles(3)
dbLoadRecords("x.db", "P=$(P)")
iocInit
makeAutosaveFileFromDbInfo("info_settings.req", "autosaveFields")
create_monitor_set("info_settings.req", 1, "")
create_monitor_set("extra.req", 1, "P=$(P)")
""")
    (tmp_path / "req" / "extra.req").write_text("file motors.req P=$(P)\n")
    (tmp_path / "autosave").mkdir()
    srv = softioc(["st.cmd"])
    assert "save_restoreSet_NumSeqFiles ignored" in srv.stderr()
    assert f"{prefix}sp.DESC" in (tmp_path / "info_settings.req").read_text()
    assert epics.caput(prefix + "plain.EGU", "mm", wait=True, timeout=5) == 1
    assert epics.caput(prefix + "plain", 3.25, wait=True, timeout=5) == 1
    assert epics.caput(prefix + "sp", -2, wait=True, timeout=5) == 1
    wait_saved(tmp_path / "autosave" / "extra.sav", f"{prefix}plain.VAL 3.25\n{prefix}plain.EGU mm\n")
    wait_saved(tmp_path / "autosave" / "info_settings.sav", f"{prefix}sp.VAL -2\n")
    srv.stop()
    forget_pvs(prefix)

    softioc(["st.cmd"])
    assert epics.caget(prefix + "plain", timeout=10) == 3.25
    assert epics.caget(prefix + "plain.EGU", timeout=5) == "mm"
    assert epics.caget(prefix + "seen", timeout=5) == -2


def test_restore_file_after_iocinit_is_an_error_with_its_line(tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    (tmp_path / "st.cmd").write_text(f'dbLoadRecords("x.db", "P={prefix}")\niocInit\nset_pass1_restoreFile("a.sav")\n')
    port = acquire_port()
    try:
        r = subprocess.run([str(BEAMCTL), "softioc", "st.cmd"], cwd=str(tmp_path), capture_output=True, text=True,
                           timeout=30, env=dict(os.environ, EPICS_CAS_SERVER_PORT=str(port),
                                                EPICS_CAS_INTF_ADDR_LIST="127.0.0.1"))
    finally:
        release_port(port)
    assert r.returncode == 1
    assert "st.cmd:3: set_pass1_restoreFile must come before iocInit" in r.stderr, r.stderr


def test_truncated_save_file_is_reported_and_the_ioc_starts(softioc, tmp_path, prefix):
    (tmp_path / "x.db").write_text(DB)
    d = tmp_path / "as"
    d.mkdir()
    (d / "info_settings.sav").write_text(f"# save/restore V5.11\n{prefix}sp.VAL 99\n{prefix}name.VAL ha")
    srv = softioc(["--autosave", "as", "-m", f"P={prefix}", "x.db"])
    assert "info_settings.sav:3: no <END> line" in srv.stderr(), srv.stderr()
    assert epics.caget(prefix + "sp", timeout=5) == 0  # nothing taken from the broken file
    srv.kill()
    forget_pvs(prefix)

    # With a good backup, synApps' fallback: the .savB values.
    (d / "info_settings.sav").write_text(f"# save/restore V5.11\n{prefix}sp.VAL 99\n{prefix}name.VAL ha")
    (d / "info_settings.savB").write_text(
        f"# save/restore V5.11\n{prefix}sp.VAL 5.5\n{prefix}gone.VAL 1\n<END>\n")
    srv = softioc(["--autosave", "as", "-m", f"P={prefix}", "x.db"])
    err = srv.stderr()
    assert "no <END> line" in err and "info_settings.savB" in err, err
    assert f"{prefix}gone.VAL: not in the database" in err, err
    assert epics.caget(prefix + "sp", timeout=10) == 5.5
    assert epics.caget(prefix + "seen", timeout=5) == 5.5
