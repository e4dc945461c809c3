"""Honest logs (issue 11): a bad BEAMCTL_LOG stops the program with what is wrong, a CA bind
failure names the address, where it came from and why, a bus outage is logged when it begins and
when it ends, and the engine statistics (latency histogram, counters) can be reset through PVs."""

import os
import re
import socket
import subprocess

import pytest
from epics import ca

from conftest import (BEAMCTL, REPO_ROOT, IocServer, RunServer, acquire_port, connect, forget_pvs, release_port,
                      require_binary, running_ioc, subscribe, wait_for)

IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: sim}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
"""

# Guard against a program that never exits (today's behaviour): not a timing assertion.
EXIT_GUARD = 60  # [s]


def run_to_exit(argv, env, cwd):
    """Runs argv until it exits; returns (exit code, stdout, stderr)."""
    require_binary()
    p = subprocess.run(argv, env=env, cwd=str(cwd), capture_output=True, text=True, timeout=EXIT_GUARD,
                       stdin=subprocess.DEVNULL)
    return p.returncode, p.stdout, p.stderr


def base_env(**extra):
    env = dict(os.environ)
    env.pop("BEAMCTL_LOG", None)
    env.update({"EPICS_CAS_AUTO_BEACON_ADDR_LIST": "NO", "EPICS_CAS_BEACON_ADDR_LIST": "127.0.0.1:9"})
    for k, v in extra.items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    return env


# ---------------------------------------------------------------------------------------------
# BEAMCTL_LOG
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("spec, bad, listing", [
    ("bogus", "unknown level 'bogus'", "trace debug info warn error off"),
    ("warn,ca=loud", "unknown level 'loud' in 'ca=loud'", "trace debug info warn error off"),
    ("warn,nosuch.logger=debug", "unknown logger 'nosuch.logger'", "ethercat.master"),
])
def test_bad_beamctl_log_is_an_error_naming_it(tmp_path, prefix, spec, bad, listing):
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name=prefix.rstrip(":"), prefix=prefix))
    port = acquire_port()
    try:
        rc, out, err = run_to_exit([str(BEAMCTL), "run", str(cfg)],
                                   base_env(BEAMCTL_LOG=spec, EPICS_CAS_SERVER_PORT=str(port),
                                            EPICS_CAS_INTF_ADDR_LIST="127.0.0.1"), tmp_path)
    finally:
        release_port(port)
    assert rc != 0, f"BEAMCTL_LOG={spec!r} was accepted: {out!r} {err[-2000:]!r}"
    assert "ready:" not in out
    assert "BEAMCTL_LOG" in err and bad in err and listing in err, err[-2000:]


def test_documented_beamctl_log_forms_still_run(tmp_path, prefix):
    """The example of docs/softioc.md (a dotted prefix `ca` of ca.server/ca.circuit) is valid."""
    port = acquire_port()
    srv = IocServer(tmp_path, [], port, name="softioc",
                    extra_env={"BEAMCTL_LOG": "warn,ca=debug,ca.circuit=trace"})
    db = tmp_path / "x.db"
    db.write_text(f'record(ao, "{prefix}x") {{ }}\n')
    srv.db_files = [str(db)]
    try:
        srv.start()
        assert srv.alive()
    finally:
        srv.stop()
        srv.kill()
        release_port(port)


# ---------------------------------------------------------------------------------------------
# CA bind failures
# ---------------------------------------------------------------------------------------------
def test_bind_failure_names_the_address_its_variable_and_the_reason(tmp_path, prefix):
    db = tmp_path / "x.db"
    db.write_text(f'record(ao, "{prefix}x") {{ }}\n')
    port = acquire_port()
    try:
        rc, out, err = run_to_exit([str(BEAMCTL), "softioc", str(db)],
                                   base_env(EPICS_CAS_INTF_ADDR_LIST="192.0.2.1",  # TEST-NET-1, not ours
                                            EPICS_CAS_SERVER_PORT=str(port)), tmp_path)
    finally:
        release_port(port)
    assert rc != 0 and "ready:" not in out
    assert f"192.0.2.1:{port}" in err, err[-2000:]
    assert "EPICS_CAS_INTF_ADDR_LIST='192.0.2.1'" in err, err[-2000:]
    assert f"EPICS_CAS_SERVER_PORT={port}" in err, err[-2000:]
    assert "Cannot assign requested address" in err, err[-2000:]
    assert "in use" not in err, err[-2000:]


def test_bind_failure_on_the_ioc_file_port_names_the_file(tmp_path, prefix):
    # A UDP port held without SO_REUSEADDR: the server's bind on it fails (EADDRINUSE).
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(IOC.format(name=prefix.rstrip(":"), prefix=prefix) + f"ca: {{port: {port}}}\n")
    try:
        rc, out, err = run_to_exit([str(BEAMCTL), "run", str(cfg)],
                                   base_env(EPICS_CAS_INTF_ADDR_LIST="127.0.0.1", EPICS_CAS_SERVER_PORT=None,
                                            EPICS_CA_SERVER_PORT=None), tmp_path)
    finally:
        holder.close()
    assert rc != 0 and "ready:" not in out
    assert f"UDP 127.0.0.1:{port}" in err, err[-2000:]
    assert f"port from {cfg}: ca: port" in err, err[-2000:]
    assert "Address already in use" in err, err[-2000:]


# ---------------------------------------------------------------------------------------------
# Bus outages
# ---------------------------------------------------------------------------------------------
STAGE = REPO_ROOT / "examples" / "sim" / "stage.yaml"

UDP_IOC = """
ioc: {{name: {name}, prefix: "{prefix}"}}
engine: {{rate_hz: 1000}}
buses:
  - id: 0
    link: {{type: udp, host: 127.0.0.1, port: {sim_port}}}
    slaves:
      - {{position: 0, type: EK1100}}
      - {{position: 1, type: EL1008}}
      - {{position: 2, type: EL7041}}
      - {{position: 3, type: EL3104}}
"""


class SimServer(IocServer):
    """`beamctl sim stage.yaml --udp PORT` (0: a free port, read from its ready line)."""

    def __init__(self, workdir, udp_port=0):
        super().__init__(workdir, [], 0, name="sim")
        self.udp_port = udp_port

    def argv(self):
        return [str(BEAMCTL), "sim", str(STAGE), "--udp", str(self.udp_port)]

    def bound_port(self):
        return int(re.search(r"udp 127\.0\.0\.1:(\d+)", self.ready_line).group(1))


def test_bus_outage_is_logged_when_it_begins_and_when_it_ends(tmp_path, prefix):
    sim = SimServer(tmp_path).start()
    run = None
    port = acquire_port()
    try:
        sim_port = sim.bound_port()
        cfg = tmp_path / "ioc.yaml"
        cfg.write_text(UDP_IOC.format(name=prefix.rstrip(":"), prefix=prefix, sim_port=sim_port))
        run = RunServer(tmp_path, cfg, port).start()
        assert wait_for(lambda: ca.get(connect(prefix + "m0-Stat-OK")) == 1, timeout=20)
        assert "bus outage" not in run.stderr()

        sim.proc.kill()  # the segment is gone: no frame comes back
        sim.proc.wait(10)
        # Logged while it lasts (before any recovery), saying what is wrong.
        assert wait_for(lambda: "ec0: bus outage: no cyclic frame comes back" in run.stderr(), timeout=20), \
            run.stderr()[-3000:]
        assert ca.get(connect(prefix + "m0-LinkUp")) == 0
        assert "bus outage ended" not in run.stderr()

        sim.udp_port = sim_port  # the segment is back (power-cycled slaves: recovered by the master)
        sim.start()
        assert wait_for(lambda: "ec0: bus outage ended after" in run.stderr(), timeout=60), run.stderr()[-3000:]
        line = next(l for l in run.stderr().splitlines() if "bus outage ended after" in l)
        assert re.search(r"ended after \d+\.\d s \(\d+ cyclic frame\(s\) lost, \d+ cycle\(s\) with a wrong working counter\)",
                         line), line
        assert wait_for(lambda: ca.get(connect(prefix + "m0-Stat-OK")) == 1, timeout=20)
    finally:
        if run is not None:
            run.stop()
            run.kill()
        sim.kill()
        forget_pvs(prefix)
        release_port(port)


# ---------------------------------------------------------------------------------------------
# Engine statistics
# ---------------------------------------------------------------------------------------------
EDGES_US = [0, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000, 20000, 50000]


def test_latency_histogram_grows_and_the_reset_pv_clears_the_statistics(tmp_path, prefix):
    with running_ioc(tmp_path, prefix, IOC):
        p = prefix + "m0-"
        edges = ca.get(connect(p + "ThdLatHistEdges"))
        assert list(edges) == EDGES_US
        hist = connect(p + "ThdLatHist")
        assert ca.element_count(hist) == len(EDGES_US)
        assert ca.field_type(hist) == ca.dbr.LONG
        cycles = connect(p + "ThdCycles")
        # Counts grow with the cycle, bucket by bucket; their sum is the cycle count.
        first = sum(ca.get(hist))
        assert wait_for(lambda: sum(ca.get(hist)) > first + 100, timeout=20)
        # Mean and max in the same unit (read in this order, the max can only have grown).
        mean, lat_max = ca.get(connect(p + "ThdLatMean")), ca.get(connect(p + "ThdLatMax"))
        assert 0 <= mean <= lat_max
        reset = connect(p + "ThdStat-Reset")
        assert ca.get(reset) == 0

        # Watch the counters: they only ever grow, except at a reset.
        col_cycles, _h1 = subscribe(cycles)
        col_hist, _h2 = subscribe(hist)
        assert col_cycles.wait_count(2) and col_hist.wait_count(2)
        before = max(col_cycles.values())
        assert ca.put(reset, 1, wait=True) == 1
        assert col_cycles.wait_value(lambda v: v < before, timeout=20), "ThdCycles never went down"

        def hist_dropped():
            sums = [int(sum(v)) for v in col_hist.values()]
            return any(b < a for a, b in zip(sums, sums[1:]))
        assert wait_for(hist_dropped, timeout=20), "the histogram was not cleared"
        assert wait_for(lambda: ca.get(reset) == 0, timeout=20), "the reset PV did not return to Done"
        # ...and grow again afterwards.
        after = ca.get(cycles)
        assert wait_for(lambda: ca.get(cycles) > after + 100, timeout=20)
        assert isinstance(ca.get(connect(p + "ThdMissedCycles")), int)
