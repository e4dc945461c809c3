"""Machine safety as a real EPICS client sees it (issue 11), on the demo beamline: virtual moves
that would take a blade past its limit are refused (through the motor record and through the
ECMC axis PVs), the virtual axes' limits follow the blades', a blade's motor record follows a move
the PLC makes, VAL starts at the readback, a refused move fails its put-callback and alarms, and
SIGTERM stops a running move and exits 0."""

import signal
import time

import epics
from epics import ca

import ca_raw
from conftest import REPO_ROOT, RunServer, acquire_port, connect, forget_pvs, release_port, wait_for

P = "DEMO:"
MSTA_PROBLEM = 1 << 9
SOFT_LIMIT_FWD = 0x114D00  # WARNING_SEQ_SETPOINT_SOFTLIM_FWD_VILOATION


def get(name):
    return ca.get(connect(P + name))


def enabled(*axes):
    for ax in axes:
        assert wait_for(lambda: get(f"{ax}-EnaAct") == 1, timeout=5), ax


class Peak:
    """The largest value a PV shows while it is monitored."""

    def __init__(self, name):
        self.max = -1e300
        self.pv = epics.PV(P + name, callback=self._cb, auto_monitor=True)
        assert self.pv.wait_for_connection(5)

    def _cb(self, value=None, **kw):
        if value is not None:
            self.max = max(self.max, value)

    def close(self):
        self.pv.disconnect()


def test_virtual_gap_past_a_blade_limit_is_refused_before_it_starts(demo):
    enabled("SlitTop", "SlitBottom", "SlitVGap", "SlitVCen")
    gap = epics.Motor(P + "SlitVGap", timeout=5)
    cen = epics.Motor(P + "SlitVCen", timeout=5)
    assert cen.move(2.5, wait=True, timeout=30) == 0
    # the gap's high limit now follows from SlitTop's DHLM (17): 2 * (17 - 2.5) = 29
    assert wait_for(lambda: abs(gap.get("DHLM") - 29.0) < 1e-3, timeout=5), gap.get("DHLM")
    top = Peak("SlitTop-PosAct")
    try:
        # pyepics refuses it from the limits alone; without that check the record refuses it (LVIO)
        assert gap.move(30, wait=True, timeout=30) == -12
        assert gap.move(30, wait=True, timeout=30, ignore_limits=True) == -4
        assert gap.get("LVIO") == 1
        assert ca.get(connect(P + "SlitVGap.SEVR")) != 0  # the virtual record alarms
        # a CA put-callback fails (ECA_PUTFAIL), as caput -c and ophyd see it
        with ca_raw.Circuit("127.0.0.1", demo.port) as c:
            ch = c.create(P + "SlitVGap")
            assert c.write_notify(ch, [30.0], dtype=ca_raw.DOUBLE).p1 == ca_raw.ECA_PUTFAIL
        time.sleep(0.3)
        assert top.max <= 17.0 + 1e-6, top.max
        assert abs(get("SlitTop-PosAct") - 2.5) < 0.01  # nothing moved (gap 0 at centre 2.5)
        # a move inside the derived range still works, and clears the alarm
        assert gap.move(10, wait=True, timeout=30) == 0
        assert ca.get(connect(P + "SlitVGap.SEVR")) == 0
        assert abs(get("SlitTop-PosAct") - 7.5) < 0.01
    finally:
        top.close()


def test_a_blade_on_its_limit_switch_stops_the_coupled_move_in_alarm(demo):
    # SlitTop's forward limit switch is at 18 mm on the stage, 12 mm on its (incremental) encoder,
    # which starts at 6 mm: a gap of 20 around 2.5 needs SlitTop at 12.5 and reaches the switch.
    enabled("SlitTop", "SlitBottom", "SlitVGap", "SlitVCen")
    gap = epics.Motor(P + "SlitVGap", timeout=5)
    cen = epics.Motor(P + "SlitVCen", timeout=5)
    assert cen.move(2.5, wait=True, timeout=30) == 0
    with ca_raw.Circuit("127.0.0.1", demo.port) as c:
        ch = c.create(P + "SlitVGap")
        assert c.write_notify(ch, [20.0], dtype=ca_raw.DOUBLE, timeout=30).p1 == ca_raw.ECA_PUTFAIL
    assert gap.get("DMOV") == 1
    assert int(gap.get("MSTA")) & MSTA_PROBLEM
    assert ca.get(connect(P + "SlitVGap.SEVR")) == 2
    assert get("SlitTop-LimFwd") == 0  # on the switch
    top, bottom = get("SlitTop-PosAct"), get("SlitBottom-PosAct")
    assert 11.5 < top < 12.5, top
    # both blades stopped together: the centre stayed where it was
    assert abs((top + bottom) / 2 - 2.5) < 0.01, (top, bottom)
    assert wait_for(lambda: "SlitTop" in epics.caget(P + "SlitVGap-MsgTxt"), timeout=5)
    assert abs(gap.get("VAL") - gap.get("RBV")) < 0.01  # VAL took the readback


def test_engine_refuses_a_virtual_move_that_bypasses_the_motor_record(demo):
    # The ECMC axis PVs go straight to the axis: the kinematics check in the cycle refuses it.
    enabled("SlitTop", "SlitBottom", "SlitVGap", "SlitVCen")
    cen = epics.Motor(P + "SlitVCen", timeout=5)
    assert cen.move(2.5, wait=True, timeout=30) == 0
    top = Peak("SlitTop-PosAct")
    try:
        epics.caput(P + "SlitVGap-MtnCmd", 3, wait=True)
        epics.caput(P + "SlitVGap-TgtPosCmd", 30, wait=True)
        epics.caput(P + "SlitVGap-ExeCmd", 1, wait=True)
        assert wait_for(lambda: get("SlitVGap-WrnId") == SOFT_LIMIT_FWD, timeout=5), get("SlitVGap-WrnId")
        assert wait_for(lambda: "SlitTop" in epics.caget(P + "SlitVGap-MsgTxt"), timeout=5), epics.caget(P + "SlitVGap-MsgTxt")
        # the record polls its axis every 0.1 s
        assert wait_for(lambda: int(epics.caget(P + "SlitVGap.MSTA")) & MSTA_PROBLEM, timeout=5)
        time.sleep(0.5)
        assert top.max <= 17.0 + 1e-6, top.max
        assert abs(get("SlitTop-PosAct") - 2.5) < 0.01
    finally:
        epics.caput(P + "SlitVGap-ExeCmd", 0, wait=True)
        top.close()


def test_a_blade_record_follows_the_move_the_plc_makes(demo):
    enabled("SlitTop", "SlitBottom", "SlitVGap", "SlitVCen")
    gap = epics.Motor(P + "SlitVGap", timeout=5)
    dmov = []
    movn = []
    pv_d = epics.PV(P + "SlitTop.DMOV", callback=lambda value=None, **k: dmov.append(value), auto_monitor=True)
    pv_m = epics.PV(P + "SlitTop.MOVN", callback=lambda value=None, **k: movn.append(value), auto_monitor=True)
    try:
        assert pv_d.wait_for_connection(5) and pv_m.wait_for_connection(5)
        assert gap.move(8, wait=True, timeout=30) == 0
        assert wait_for(lambda: dmov and dmov[-1] == 1, timeout=5)
        assert 0 in dmov, dmov  # the blade's record showed the move
        assert 1 in movn, movn
        top = epics.Motor(P + "SlitTop", timeout=5)
        assert wait_for(lambda: abs(top.get("VAL") - 4.0) < 0.01, timeout=5), top.get("VAL")
        assert abs(top.get("VAL") - top.get("RBV")) < 0.01
        assert top.get("DMOV") == 1 and top.get("MOVN") == 0
    finally:
        pv_d.disconnect()
        pv_m.disconnect()


def test_val_starts_at_the_readback_and_a_tweak_goes_forward(demo):
    x = epics.Motor(P + "SampleX", timeout=5)
    # the absolute encoder reads 1.5 mm at start (the record's first poll after the bus is OK
    # brings the readback, up to 0.1 s after the bus status PV says OK)
    assert wait_for(lambda: abs(x.get("RBV") - 1.5) < 1e-3, timeout=5), x.get("RBV")
    rbv = x.get("RBV")
    assert abs(x.get("VAL") - rbv) < 1e-3 and abs(x.get("DVAL") - x.get("DRBV")) < 1e-3
    epics.caput(P + "SampleX-EnaCmd", 1, wait=True)
    assert wait_for(lambda: get("SampleX-EnaAct") == 1, timeout=5)
    twv = x.get("TWV")
    x.put("TWF", 1, wait=True, timeout=30)
    assert wait_for(lambda: x.get("DMOV") == 1, timeout=30)
    assert x.get("RBV") > rbv + 0.5 * twv, (rbv, x.get("RBV"), twv)


def test_a_refused_move_fails_its_put_callback_and_alarms(demo):
    x = epics.Motor(P + "SampleX", timeout=5)
    epics.caput(P + "SampleX-EnaCmd", 0, wait=True)
    assert wait_for(lambda: get("SampleX-EnaAct") == 0, timeout=5)
    start = x.get("RBV")
    with ca_raw.Circuit("127.0.0.1", demo.port) as c:
        ch = c.create(P + "SampleX")
        assert c.write_notify(ch, [start + 2.0], dtype=ca_raw.DOUBLE).p1 == ca_raw.ECA_PUTFAIL
    assert wait_for(lambda: int(x.get("MSTA")) & MSTA_PROBLEM, timeout=5)
    assert ca.get(connect(P + "SampleX.SEVR")) == 2  # MAJOR: what ophyd's EpicsMotor checks on RBV
    assert x.get("DMOV") == 1
    assert abs(x.get("VAL") - start) < 1e-3  # targets back at the readback: nothing moved
    # pyepics ignores the put-callback status; its Motor.move reports only LVIO/HLS/LLS
    # (docs/motion.md): the failure is visible in MSTA and the severity
    x.move(start + 2.0, wait=True, timeout=30)
    assert ca.get(connect(P + "SampleX.SEVR")) == 2


def test_sigterm_stops_a_running_move_disables_the_drives_and_exits_0(tmp_path):
    port = acquire_port()
    srv = RunServer(tmp_path, REPO_ROOT / "examples" / "demo" / "ioc.yaml", port).start()
    try:
        assert wait_for(lambda: ca.get(connect(P + "m0-Stat-OK")) == 1, timeout=10)
        enabled("SlitTop")
        top = epics.Motor(P + "SlitTop", timeout=5)
        top.move(12, wait=False)
        assert wait_for(lambda: abs(get("SlitTop-VelAct")) > 1.0, timeout=5)
        srv.proc.send_signal(signal.SIGTERM)
        assert srv.proc.wait(20) == 0
        out = "\n".join(srv.stdout_lines)
        assert "stopping" in out, out
        err = srv.stderr()
        assert "stopped" in err and "still moved" not in err and "still enabled" not in err, err
        assert "SAFEOP" not in err or "no answer" not in err, err
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(P)
        release_port(port)


class Last:
    """Every value a PV's monitor delivers, in order."""

    def __init__(self, name):
        self.values = []
        self.pv = epics.PV(P + name, callback=self._cb, auto_monitor=True)
        assert self.pv.wait_for_connection(5)

    def _cb(self, value=None, **kw):
        if value is not None:
            self.values.append(value)


def test_sigterm_during_a_move_posts_the_stopped_state_before_the_server_closes(tmp_path):
    """Clients see the move end (DMOV 1, MOVN 0, the stopped readback) before the disconnect, and
    the log names each axis's final position."""
    port = acquire_port()
    srv = RunServer(tmp_path, REPO_ROOT / "examples" / "demo" / "ioc.yaml", port).start()
    try:
        assert wait_for(lambda: ca.get(connect(P + "m0-Stat-OK")) == 1, timeout=10)
        enabled("SlitTop")
        dmov, movn, rbv = Last("SlitTop.DMOV"), Last("SlitTop.MOVN"), Last("SlitTop.RBV")
        top = epics.Motor(P + "SlitTop", timeout=5)
        start = top.get("RBV")
        top.move(start + 8 if start < 5 else start - 8, wait=False)
        assert wait_for(lambda: dmov.values and dmov.values[-1] == 0, timeout=5)
        assert wait_for(lambda: abs(get("SlitTop-VelAct")) > 1.0, timeout=5)
        srv.proc.send_signal(signal.SIGTERM)
        assert srv.proc.wait(20) == 0
        time.sleep(0.5)  # the last monitor updates were sent before the close; let libca deliver them
        assert dmov.values[-1] == 1, dmov.values
        assert movn.values[-1] == 0, movn.values
        final = rbv.values[-1]
        err = srv.stderr()
        assert "stopped: axis" in err, err
        line = [x for x in err.splitlines() if "stopped: axis" in x and "SlitTop" in x]
        assert line, err
        logged = float(line[0].split(" at ")[1].split()[0])
        assert abs(logged - final) < 0.01, (logged, final)  # the last RBV a client saw is where it stopped
        assert abs(final - start) > 0.01  # it had moved: the stop is mid-move, not a stale value
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(P)
        release_port(port)


def test_outputs_an_axis_drives_are_read_only_and_show_what_is_sent(demo):
    enabled("SlitTop")
    vel = epics.PV(P + "m0s011-velocitySetpoint01")
    ctrl = epics.PV(P + "m0s011-driveControl01")
    assert vel.wait_for_connection(5) and ctrl.wait_for_connection(5)
    assert not vel.write_access and not ctrl.write_access
    assert "SlitTop" in epics.caget(P + "m0s011-velocitySetpoint01.DESC")
    # the control word of an enabled drive has its enable bit set, and the PV is not UDF/INVALID
    assert wait_for(lambda: int(ctrl.get(use_monitor=False)) & 1 == 1, timeout=5), ctrl.get()
    assert ca.get(connect(P + "m0s011-driveControl01.SEVR")) == 0
    # a put is refused and changes nothing
    with ca_raw.Circuit("127.0.0.1", demo.port) as c:
        ch = c.create(P + "m0s011-velocitySetpoint01")
        assert ch["access"] & 2 == 0  # no write access
        assert c.write_notify(ch, [10000.0], dtype=ca_raw.DOUBLE).p1 != ca_raw.ECA_NORMAL
    assert vel.get(use_monitor=False) == 0
    # while the blade moves, the PV shows the velocity sent to the drive
    top = epics.Motor(P + "SlitTop", timeout=5)
    top.move(4, wait=False)
    assert wait_for(lambda: abs(vel.get(use_monitor=False)) > 1000, timeout=5), vel.get()
    assert wait_for(lambda: top.get("DMOV") == 1, timeout=30)
