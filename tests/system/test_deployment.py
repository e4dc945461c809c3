"""Deployment (docs/deployment.md): the systemd units in deploy/systemd are valid for systemd
(`systemd-analyze verify`, with the unit's binary path pointed at the build), and a process without
CAP_SYS_NICE and CAP_IPC_LOCK runs with normal scheduling and says in one line what it could not
get and which capability or limit grants it."""

import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from conftest import BEAMCTL, REPO_ROOT, ScannerServer, require_binary, wait_for

UNITS = sorted((REPO_ROOT / "deploy" / "systemd").glob("*.service"))


def test_the_units_are_there():
    assert [u.name for u in UNITS] == ["beamctl-ioc@.service", "beamctl-scanner@.service"]


@pytest.mark.parametrize("unit", UNITS, ids=lambda u: u.name)
def test_systemd_accepts_the_unit(unit, tmp_path):
    if not shutil.which("systemd-analyze"):
        pytest.skip("systemd-analyze is not installed on this machine")
    require_binary()
    text = unit.read_text()
    assert "/usr/local/bin/beamctl" in text
    inst = tmp_path / unit.name.replace("@.", "@test.")
    inst.write_text(text.replace("/usr/local/bin/beamctl", str(BEAMCTL)))
    r = subprocess.run(["systemd-analyze", "verify", str(inst)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "" and r.stderr.strip() == "", r.stdout + r.stderr
    for cap in ("CAP_SYS_NICE", "CAP_IPC_LOCK", "CAP_NET_RAW"):
        assert re.search(r"^AmbientCapabilities=.*" + cap, text, re.M), cap
    assert re.search(r"^LimitMEMLOCK=infinity$", text, re.M) and re.search(r"^LimitRTPRIO=\d+$", text, re.M)


def test_without_the_capabilities_it_says_what_it_could_not_get(tmp_path):
    require_binary()
    capsh = shutil.which("capsh")
    if not capsh:
        pytest.skip("capsh (libcap2-bin) is not installed: cannot drop capabilities")
    # A scanner of the example, its socket in tmp: started with CAP_SYS_NICE and CAP_IPC_LOCK dropped
    # from the bounding set and no RT priority or memlock allowance.
    cfg = (REPO_ROOT / "examples" / "scanner" / "scanner.yaml").read_text()
    cfg = re.sub(r"socket: [^\s,}]+", f"socket: {tmp_path}/s.sock", cfg)
    (tmp_path / "scanner.yaml").write_text(cfg)
    shutil.copy(REPO_ROOT / "examples" / "scanner" / "plant.yaml", tmp_path / "plant.yaml")
    argv = [capsh, "--drop=cap_sys_nice,cap_ipc_lock", "--", "-c",
            f"ulimit -r 0; ulimit -l 64; exec {BEAMCTL} scanner {tmp_path}/scanner.yaml"]
    srv = ScannerServer(tmp_path, tmp_path / "scanner.yaml")
    srv.argv = lambda: argv
    srv.start()
    try:
        assert wait_for(lambda: "RT cycle at" in srv.stderr(), timeout=10), srv.stderr()
        line = next(l for l in srv.stderr().splitlines() if "RT cycle at" in l)
        assert "SCHED_FIFO refused (Operation not permitted): normal scheduling; grant CAP_SYS_NICE or an RT priority limit (LimitRTPRIO=80)" in line, line
        assert "mlockall refused" in line and "grant CAP_IPC_LOCK or raise the memlock limit (LimitMEMLOCK=infinity)" in line, line
        # and it runs: the cycle advances
        def cycle():
            r = subprocess.run([str(BEAMCTL), "scanner", "status", f"{tmp_path}/s.sock"], capture_output=True, text=True, timeout=10)
            m = re.match(r"cycle (\d+)", r.stdout)
            return int(m.group(1)) if m else -1
        c0 = cycle()
        assert c0 >= 0
        assert wait_for(lambda: cycle() > c0 + 100, timeout=10)
    finally:
        srv.stop()
        srv.kill()
