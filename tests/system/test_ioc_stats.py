"""IOC health PVs as devIocStats names them (issue 41, item 8), read with pyepics on the real libca:
`beamctl run` serves $(IOC):HEARTBEAT, UPTIME, IOC_CPU_LOAD, CPU_CNT, MEM_USED, MEM_FREE, FD_CNT,
CA_CLNT_CNT, CA_CONN_CNT, START_CNT, EPICS_VERS ... for `ioc.stats` (the IOC's name by default);
`beamctl softioc --ioc-stats NAME` loads the same set; a database written for devIocStats
(DTYP "IOC stats", "IOC env var") loads in softioc as it is."""

import os
import re

from conftest import (IocServer, RunServer, acquire_port, connect, forget_pvs, not_connecting,
                      release_port, require_binary, wait_for)

from epics import ca


def get(name, **kw):
    return ca.get(connect(name), **kw)


def check_health_pvs(ioc, pid):
    assert get(f"{ioc}:CPU_CNT") == os.cpu_count()
    assert get(f"{ioc}:PROCESS_ID") == pid
    assert get(f"{ioc}:FD_CNT") > 2
    assert get(f"{ioc}:FD_FREE") == get(f"{ioc}:FD_MAX") - get(f"{ioc}:FD_CNT")
    assert get(f"{ioc}:MEM_USED") > 1e6
    assert 0 < get(f"{ioc}:MEM_FREE") < get(f"{ioc}:MEM_MAX")
    assert 0 <= get(f"{ioc}:IOC_CPU_LOAD") <= 100
    assert get(f"{ioc}:START_CNT") == 1
    assert "beamctl" in get(f"{ioc}:EPICS_VERS") and "EPICS 7.0.8" in get(f"{ioc}:EPICS_VERS")
    assert re.fullmatch(r"(\d+ days?, )?\d\d:\d\d:\d\d", get(f"{ioc}:UPTIME"))
    # HEARTBEAT counts seconds: it moves on while we watch
    beat = get(f"{ioc}:HEARTBEAT")
    assert wait_for(lambda: get(f"{ioc}:HEARTBEAT") >= beat + 2, timeout=10)
    # the CA counts are sampled every CA_UPD_TIME (15 s): a shorter period samples at once, and
    # this client (with the channels it opened) is counted
    assert ca.put(connect(f"{ioc}:CA_UPD_TIME"), 1, wait=True) == 1
    assert wait_for(lambda: get(f"{ioc}:CA_CLNT_CNT") >= 1, timeout=10)
    assert wait_for(lambda: get(f"{ioc}:CA_CONN_CNT") >= 12, timeout=10)


def test_run_serves_devIocStats_names_under_the_ioc_name(tmp_path):
    require_binary()
    name = f"ST{os.getpid() % 100000}"
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(f"ioc: {{name: {name}, prefix: '{name}:'}}\n")
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    try:
        srv.start()
        check_health_pvs(name, srv.proc.pid)
        assert get(f"{name}:LOAD") == get(f"{name}:IOC_CPU_LOAD")  # devIocStats's alias
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(f"{name}:")
        release_port(port)


def test_stats_false_leaves_them_out_and_a_name_sets_IOC(tmp_path):
    require_binary()
    name = f"SN{os.getpid() % 100000}"
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(f"ioc: {{name: {name}, stats: 'IOC:{name}'}}\n")
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    try:
        srv.start()
        assert get(f"IOC:{name}:CPU_CNT") == os.cpu_count()
        assert not_connecting(f"{name}:CPU_CNT")
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(f"IOC:{name}:")
        release_port(port)
    # stats: false
    cfg.write_text(f"ioc: {{name: {name}, stats: false}}\n")
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    try:
        srv.start()
        assert "0 PVs" in srv.ready_line, srv.ready_line
        assert not_connecting(f"{name}:HEARTBEAT")
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(f"{name}:")
        release_port(port)


class StatsSoftIoc(IocServer):
    def __init__(self, workdir, db_files, port, ioc):
        super().__init__(workdir, db_files, port)
        self.ioc = ioc

    def argv(self):
        return super().argv()[:2] + ["--ioc-stats", self.ioc] + super().argv()[2:]


def test_softioc_loads_the_set_and_databases_written_for_devIocStats(tmp_path):
    require_binary()
    ioc = f"SS{os.getpid() % 100000}"
    db = tmp_path / "site.db"
    # the way sites extend iocAdmin: their own records on devIocStats's device supports
    db.write_text(f"""
record(stringin, "{ioc}:SITE") {{ field(DTYP, "IOC env var") field(INP, "@BEAMCTL_SITE") field(PINI, "YES") }}
record(stringin, "{ioc}:RPTR") {{ field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_REPEATER_PORT") field(PINI, "YES") }}
record(ai, "{ioc}:OWN_FDS") {{ field(DTYP, "IOC stats") field(INP, "@fd") field(SCAN, "I/O Intr") }}
""")
    port = acquire_port()
    srv = StatsSoftIoc(tmp_path, [db], port, ioc)
    srv.extra_env["BEAMCTL_SITE"] = "beamline 7"
    try:
        srv.start()
        check_health_pvs(ioc, srv.proc.pid)
        assert get(f"{ioc}:SITE") == "beamline 7"
        assert get(f"{ioc}:RPTR") == os.environ.get("EPICS_CA_REPEATER_PORT", "5065")
        assert get(f"{ioc}:OWN_FDS") > 2
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(f"{ioc}:")
        release_port(port)


def test_readacf_rereads_the_acf_and_sysreset_stops_the_ioc_cleanly(tmp_path):
    """devIocStats's READACF (asSubProcess) and SYSRESET (rebootProc), as a facility's admin
    screen drives them: a put of 1 to READACF re-reads the ACF (a broken file raises BRSV and
    keeps the old rules); SYSRESET.PROC stops the IOC as SIGTERM does, exit status 0."""
    require_binary()
    name = f"SR{os.getpid() % 100000}"
    acf = tmp_path / "ioc.acf"
    acf.write_text("ASG(DEFAULT) {\n  RULE(1, WRITE)\n}\n")
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(f"ioc: {{name: {name}}}\nca: {{acf: {acf}}}\n")
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    try:
        srv.start()
        readacf = connect(f"{name}:READACF")
        assert ca.put(readacf, 1, wait=True) == 1
        assert wait_for(lambda: ca.get(readacf) == 0, timeout=5)
        assert get(f"{name}:READACF.SEVR") == 0  # NO_ALARM
        acf.write_text("ASG(DEFAULT) {\n  RULE(1, WRITE\n")  # broken: the old rules stay
        assert ca.put(readacf, 1, wait=True) == 1
        assert wait_for(lambda: get(f"{name}:READACF.SEVR") == 3, timeout=5)  # INVALID (BRSV)
        assert ca.put(connect(f"{name}:SYSRESET.PROC"), 1, wait=True) == 1
        assert srv.proc.wait(timeout=20) == 0
        assert wait_for(lambda: any("stopping: stopping axes" in l for l in srv.stdout_lines), timeout=5), srv.stdout_lines
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(f"{name}:")
        release_port(port)
