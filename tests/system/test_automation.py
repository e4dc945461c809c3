"""Automation (docs/automation.md) with a real EPICS client: the split-and-delay example's virtual
motors (examples/snd, seed 003) moved with put-callbacks move every real axis to the seed's
geometry; a move beyond the reals' limits is refused before anything moves; a stopped move fails;
and a compound motor drives another IOC's motor records through Channel Access."""

import ctypes
import math
import time
from pathlib import Path

import epics
from epics import ca

from conftest import (_put_done, ECA_NORMAL, ECA_PUTFAIL, IocServer, RunServer, acquire_port, connect, forget_pvs, put_status,
                      release_port, require_binary, running_config, wait_for)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
HC, D_SI220, C_MM_PS, GAP = 12.398419843320026, 1.920155716, 0.299792458, 55.0


def get(name, **kw):
    return ca.get(connect(name), **kw)


def bragg(kev):
    return math.degrees(math.asin(HC / (2 * D_SI220 * kev)))


def snd_config(prefix, mail_port=None, http_port=None):
    """examples/snd/ioc.yaml under `prefix`, its files found, its mail and webhook servers moved."""
    d = EXAMPLES / "snd"
    cfg = (d / "ioc.yaml").read_text()
    cfg = cfg.replace("ioc: {name: SND}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    cfg = cfg.replace("file: snd_", f"file: {d}/snd_").replace('"SND:', f'"{prefix}')
    if mail_port:
        cfg = cfg.replace("port: 8025", f"port: {mail_port}")
    if http_port:
        cfg = cfg.replace("127.0.0.1:8026", f"127.0.0.1:{http_port}")
    assert '"SND:' not in cfg
    return cfg


def running_snd(tmp_path, prefix):
    return running_config(tmp_path, prefix, snd_config(prefix), lambda: abs(get(prefix + "E1.RBV") - 8.0) < 1e-3, timeout=20)


def test_e1_moves_every_crystal_arm_and_the_diagnostic(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        assert abs(get(prefix + "E1.VAL") - 8.0) < 1e-3  # VAL starts at the readback
        assert put_status(prefix + "E1", 9.5, timeout=60) == ECA_NORMAL
        th = bragg(9.5)
        for axis in ("T1:TH1", "T1:TH2", "T4:TH1", "T4:TH2"):
            assert abs(get(prefix + axis + ".RBV") - th) < 2e-4, axis
        for axis in ("T1:TTH", "T4:TTH"):
            assert abs(get(prefix + axis + ".RBV") - 2 * th) < 2e-4, axis
        length = get(prefix + "T1:L.RBV")
        assert abs(get(prefix + "DD:X.RBV") - length * math.sin(math.radians(2 * th))) < 2e-3  # Eq. 2
        assert abs(get(prefix + "E1.RBV") - 9.5) < 1e-4
        assert get(prefix + "E1.DMOV") == 1
        # the channel-cut branch did not move
        assert abs(get(prefix + "T2:TH.RBV") - bragg(8.0)) < 2e-4
        # E2: T2/T3's crystals and dcc.x = 2 gap cos theta2 (Eq. 3)
        assert put_status(prefix + "E2", 7.0, timeout=60) == ECA_NORMAL
        th2 = bragg(7.0)
        assert abs(get(prefix + "T3:TH.RBV") - th2) < 2e-4
        assert abs(get(prefix + "DCC:X.RBV") - 2 * GAP * math.cos(math.radians(th2))) < 2e-3


def test_delay_moves_the_delay_stages_to_eq1(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        assert put_status(prefix + "Delay", 100.0, timeout=60) == ECA_NORMAL
        th1, th2 = math.radians(bragg(8.0)), math.radians(bragg(8.0))
        length = (100.0 * C_MM_PS / 2 + GAP * (1 - math.cos(2 * th2)) / math.sin(th2)) / (1 - math.cos(2 * th1))
        for axis in ("T1:L", "T4:L"):
            assert abs(get(prefix + axis + ".RBV") - length) < 2e-3, axis
        assert abs(get(prefix + "DD:X.RBV") - length * math.sin(2 * th1)) < 2e-3
        assert abs(get(prefix + "Delay.RBV") - 100.0) < 0.05


def test_a_move_beyond_a_reals_limits_is_refused_and_nothing_moves(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        # the virtual's limits follow the reals': th within [5, 80] degrees
        assert abs(get(prefix + "E1.LLM") - HC / (2 * D_SI220 * math.sin(math.radians(80)))) < 1e-3
        # narrow one crystal's range: th1 <= 26 degrees, i.e. E1 >= 7.37 keV
        assert put_status(prefix + "T4:TH2.HLM", 26.0) == ECA_NORMAL
        e_low = HC / (2 * D_SI220 * math.sin(math.radians(26.0)))
        assert wait_for(lambda: abs(get(prefix + "E1.LLM") - e_low) < 1e-3, 5), get(prefix + "E1.LLM")
        before = {a: get(prefix + a + ".RBV") for a in ("T1:TH1", "T4:TH2", "T1:TTH", "DD:X")}
        assert put_status(prefix + "E1", 7.0, timeout=30) == ECA_PUTFAIL
        assert get(prefix + "E1.LVIO") == 1
        time.sleep(0.5)
        assert {a: get(prefix + a + ".RBV") for a in before} == before
        # still movable within them
        assert put_status(prefix + "E1", 7.5, timeout=60) == ECA_NORMAL


def test_a_stopped_move_fails_its_put_callback(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        got = []
        chid = connect(prefix + "E1")
        data = (ctypes.c_double * 1)(4.0)  # theta 23.8 -> 53.8 degrees at 5 deg/s: about 6 s
        assert epics.ca.libca.ca_array_put_callback(6, 1, chid, data, _put_done, ctypes.py_object(got)) == ECA_NORMAL
        epics.ca.flush_io()
        assert wait_for(lambda: get(prefix + "E1.DMOV") == 0, 5)
        time.sleep(1.0)
        assert not got
        epics.caput(prefix + "E1.STOP", 1)
        assert wait_for(lambda: got, 10)
        assert got[0] == ECA_PUTFAIL  # it ended short: never a success
        assert get(prefix + "E1.DMOV") == 1
        th = get(prefix + "T1:TH1.RBV")
        assert 24 < th < 50
        time.sleep(0.5)
        assert get(prefix + "T1:TH1.RBV") == th  # the reals stopped
        assert abs(get(prefix + "E1.RBV") - 4.0) > 0.5


MOTORS_DB = """
record(motor, "$(P)th")  { field(DTYP, "Sim Motor") field(MRES, "0.0001") field(RDBD, "0.0001") field(VELO, "10") field(ACCL, "0.1")
                           field(DLLM, "5") field(DHLM, "80") field(DVAL, "20") }
record(motor, "$(P)tth") { field(DTYP, "Sim Motor") field(MRES, "0.0001") field(RDBD, "0.0001") field(VELO, "20") field(ACCL, "0.1")
                           field(DLLM, "10") field(DHLM, "160") field(DVAL, "40") }
"""


def test_a_compound_motor_drives_another_iocs_motors_through_ca(tmp_path, prefix):
    """IOC A serves two motor records (beamctl softioc); IOC B's compound motor E moves them."""
    require_binary()
    a_prefix = prefix + "A:"
    (tmp_path / "motors.db").write_text(MOTORS_DB)
    a_port = acquire_port()
    a = IocServer(tmp_path, [tmp_path / "motors.db"], a_port, macros=f"P={a_prefix}", name="motors").start()
    try:
        theta = "asin(12.398419843320026 / (2 * 1.920155716 * E))"
        cfg = f"""ioc: {{name: B, prefix: "{prefix}"}}
compound_motors:
  - name: energy
    reals: {{th: "{a_prefix}th", tth: "{a_prefix}tth"}}
    virtuals:
      E: {{forward: "12.398419843320026 / (2 * 1.920155716 * sin(th * pi / 180))", egu: keV, prec: 4}}
    inverse:
      th: "{theta} * 180 / pi"
      tth: "2 * {theta} * 180 / pi"
"""
        (tmp_path / "b.yaml").write_text(cfg)
        b_port = acquire_port()
        b = RunServer(tmp_path, tmp_path / "b.yaml", b_port)
        b.extra_env = {"EPICS_CA_ADDR_LIST": f"127.0.0.1:{a_port}", "EPICS_CA_AUTO_ADDR_LIST": "NO"}
        b.start()
        try:
            e0 = HC / (2 * D_SI220 * math.sin(math.radians(20)))
            assert wait_for(lambda: abs(get(prefix + "E.RBV") - e0) < 1e-3, 20), get(prefix + "E.RBV")
            assert put_status(prefix + "E", 8.0, timeout=60) == ECA_NORMAL
            assert abs(get(a_prefix + "th.RBV") - bragg(8.0)) < 2e-4
            assert abs(get(a_prefix + "tth.RBV") - 2 * bragg(8.0)) < 2e-4
            assert abs(get(prefix + "E.RBV") - 8.0) < 1e-4
            # beyond the remote reals' limits (th >= 5 degrees -> E <= 37 keV): refused, nothing moves
            assert put_status(prefix + "E", 40.0, timeout=30) == ECA_PUTFAIL
            assert abs(get(a_prefix + "th.RBV") - bragg(8.0)) < 2e-4
            # the other IOC goes away: the compound motor says so (an invalid alarm), and comes back
            a.stop()
            assert wait_for(lambda: get(prefix + "E.SEVR") == 3, 30), get(prefix + "E.SEVR")
            a.start()  # its simulated motors start again at th 20, tth 40 degrees
            assert wait_for(lambda: get(prefix + "E.SEVR") < 3 and abs(get(prefix + "E.RBV") - e0) < 1e-3, 30)
            assert put_status(prefix + "E", 9.0, timeout=60) == ECA_NORMAL
            assert abs(get(prefix + "E.RBV") - 9.0) < 1e-4  # A's th, read through B (this client's own
            assert get(prefix + "E.SEVR") == 0               # channels to A may still be searching)
        finally:
            b.stop()
            b.kill()
            release_port(b_port)
    finally:
        a.stop()
        a.kill()
        forget_pvs(prefix)
        release_port(a_port)


def get_str(name):
    connect(name)
    return epics.caget(name, as_string=True)  # an enum's state string (ca.get would give the index)


def wait_state(prefix, machine, state, timeout=10):
    return wait_for(lambda: get_str(f"{prefix}{machine}:State") == state, timeout)


def test_the_primary_state_machine_latches_and_the_ack_names_who(tmp_path, prefix):
    """The example's FSM: unparking while the tower is not flying latches; the latch refuses every
    request until Ack, which names the client (user@host); the auxiliary bearing machine flies the
    tower; a tower that lands on its own in normal operation latches again."""
    import getpass
    import socket
    with running_snd(tmp_path, prefix):
        fsm, bearing = prefix + "snd:", prefix + "bearing_t1:"
        assert get_str(fsm + "State") == "parked"
        assert get_str(fsm + "Allowed") == "normal_operation, access_mode"
        assert put_status(fsm + "Request", "normal_operation") == ECA_PUTFAIL  # its guard: tower 1 flying
        assert wait_state(prefix, "snd", "error_latch")
        assert get(fsm + "Latched") == 1
        assert get_str(fsm + "Error") == "guard of transition unpark does not hold: bearing_t1 == bearing_t1.flying"
        assert put_status(fsm + "Request", "access_mode") == ECA_PUTFAIL  # latched: refused
        assert get_str(fsm + "State") == "error_latch"
        assert put_status(fsm + "Ack", 1) == ECA_NORMAL
        assert wait_state(prefix, "snd", "parked")
        assert get_str(fsm + "AckBy") == f"{getpass.getuser()}@{socket.gethostname()}"[:39]
        # the air bearing: locked -> landed -> flying (valves, then the pressure switch)
        assert put_status(bearing + "Request", "landed") == ECA_NORMAL
        assert wait_state(prefix, "bearing_t1", "landed")
        assert get(prefix + "T1:Vacuum") == 0
        assert put_status(bearing + "Request", "flying") == ECA_NORMAL
        assert wait_state(prefix, "bearing_t1", "flying")
        assert get(prefix + "T1:Floating") == 1
        assert put_status(fsm + "Request", "normal_operation") == ECA_NORMAL
        assert wait_state(prefix, "snd", "normal_operation")
        # the tower lands on its own: normal operation's invariant latches
        epics.caput(prefix + "T1:N2", 0)
        assert wait_state(prefix, "snd", "error_latch")
        assert get_str(fsm + "Error") == "the invariant of normal_operation no longer holds: floating_t1 == 1"


def test_parking_runs_the_auxiliary_machines_transitions(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        fsm, bearing = prefix + "snd:", prefix + "bearing_t1:"
        for state in ("landed", "flying"):
            assert put_status(bearing + "Request", state) == ECA_NORMAL
            assert wait_state(prefix, "bearing_t1", state)
        assert put_status(fsm + "Request", "normal_operation") == ECA_NORMAL
        assert wait_state(prefix, "snd", "normal_operation")
        assert put_status(fsm + "Request", "parked") == ECA_NORMAL  # lands and locks tower 1 first
        assert wait_for(lambda: get(fsm + "Busy") == 1 or get_str(fsm + "State") == "parked", 5)
        assert wait_state(prefix, "snd", "parked")
        assert get_str(bearing + "State") == "locked"
        assert get(prefix + "T1:N2") == 0 and get(prefix + "T1:Vacuum") == 1
        assert get(fsm + "Latched") == 0


class MailAndHooks:
    """A local SMTP server (Debian's python3-aiosmtpd) and an HTTP server that record what arrives."""

    def __init__(self):
        import http.server
        import threading
        from aiosmtpd.controller import Controller

        self.mails, self.posts = [], []
        outer = self

        class Handler:
            async def handle_DATA(self, server, session, envelope):
                outer.mails.append((envelope.mail_from, list(envelope.rcpt_tos), envelope.content.decode()))
                return "250 OK"

        import socket
        probe = socket.socket()
        probe.bind(("127.0.0.1", 0))
        self.smtp_port = probe.getsockname()[1]  # a free port (Controller cannot take port 0)
        probe.close()
        self.smtp = Controller(Handler(), hostname="127.0.0.1", port=self.smtp_port)
        self.smtp.start()

        class Hook(http.server.BaseHTTPRequestHandler):
            def do_POST(self):
                body = self.rfile.read(int(self.headers["Content-Length"]))
                outer.posts.append((self.path, self.headers["Content-Type"], body.decode()))
                self.send_response(204)
                self.end_headers()

            def log_message(self, *args):
                pass

        self.http = http.server.HTTPServer(("127.0.0.1", 0), Hook)
        self.http_port = self.http.server_address[1]
        threading.Thread(target=self.http.serve_forever, daemon=True).start()

    def close(self):
        self.smtp.stop()
        self.http.shutdown()


def test_a_latch_sends_an_email_and_a_webhook_once(tmp_path, prefix):
    import json
    srv = MailAndHooks()
    try:
        cfg = snd_config(prefix, srv.smtp_port, srv.http_port)
        with running_config(tmp_path, prefix, cfg, lambda: get_str(prefix + "snd:State") == "parked", timeout=20):
            assert put_status(prefix + "snd:Request", "normal_operation") == ECA_PUTFAIL  # the guard: latches
            assert wait_for(lambda: srv.mails and srv.posts, 10), (srv.mails, srv.posts)
            mail_from, rcpt, content = srv.mails[0]
            assert mail_from == "snd-ioc@localhost" and rcpt == ["snd-engineers@localhost"]
            assert "Subject: [beamctl] state machine snd latched" in content
            assert "guard of transition unpark does not hold: bearing_t1 == bearing_t1.flying" in content
            path, ctype, body = srv.posts[0]
            assert path == "/snd" and ctype == "application/json"
            assert json.loads(body)["subject"] == "[beamctl] state machine snd latched"
            assert wait_for(lambda: get(prefix + "notify:Sent") == 1, 5)
            # acknowledged and latched again the same way within a minute: not sent again
            assert put_status(prefix + "snd:Ack", 1) == ECA_NORMAL
            assert put_status(prefix + "snd:Request", "normal_operation") == ECA_PUTFAIL
            assert wait_for(lambda: get(prefix + "notify:Suppressed") == 1, 5)
            time.sleep(0.5)
            assert len(srv.mails) == 1 and len(srv.posts) == 1
    finally:
        srv.close()


def test_an_unreachable_mail_server_is_retried_logged_and_never_blocks_control(tmp_path, prefix):
    srv = MailAndHooks()
    port = srv.smtp_port
    srv.close()  # nobody listens there now
    cfg = snd_config(prefix, port).replace('  webhooks: ["http://127.0.0.1:8026/snd"]\n', "")
    cfg = cfg.replace("  min_interval: 60", "  min_interval: 60\n  retries: 2\n  retry_interval: 0.2")
    with running_config(tmp_path, prefix, cfg, lambda: get_str(prefix + "snd:State") == "parked", timeout=20):
        assert put_status(prefix + "snd:Request", "normal_operation") == ECA_PUTFAIL
        assert wait_for(lambda: get(prefix + "notify:Failed") == 1, 10)
        assert get(prefix + "notify:Sent") == 0
        assert get_str(prefix + "notify:LastError").startswith("given up after 3 attempts: cannot connect to 127.0.0.1")
        # control went on meanwhile
        assert put_status(prefix + "snd:Ack", 1) == ECA_NORMAL
        assert put_status(prefix + "E1", 8.5, timeout=60) == ECA_NORMAL


def test_a_pv_reaching_its_alarm_severity_posts_a_webhook(tmp_path, prefix):
    import json
    srv = MailAndHooks()
    try:
        (tmp_path / "t.db").write_text(f'record(ao, "{prefix}temp") {{ field(HIHI, "50") field(HHSV, "MAJOR") field(HIGH, "40") field(HSV, "MINOR") }}\n')
        cfg = f"""ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}
db: [{{file: t.db}}]
notify:
  webhooks: ["http://127.0.0.1:{srv.http_port}/alarm"]
  rules: [{{pv: "{prefix}temp", severity: MAJOR}}]
  min_interval: 0
"""
        with running_config(tmp_path, prefix, cfg, lambda: get(prefix + "notify:Sent") == 0, timeout=20):
            epics.caput(prefix + "temp", 45, wait=True)  # MINOR: below the rule's severity
            time.sleep(0.3)
            assert srv.posts == []
            epics.caput(prefix + "temp", 60, wait=True)  # MAJOR
            assert wait_for(lambda: srv.posts, 10)
            msg = json.loads(srv.posts[0][2])
            assert msg["subject"] == f"[beamctl] {prefix}temp in MAJOR alarm"
            assert msg["text"].startswith(f"{prefix}temp = 60, severity MAJOR")
            epics.caput(prefix + "temp", 61, wait=True)  # still MAJOR: no new message (edges only)
            time.sleep(0.3)
            assert len(srv.posts) == 1
    finally:
        srv.close()


def test_the_collision_zone_refuses_a_move_into_it_and_stops_a_jog(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        assert put_status(prefix + "T1:X", 60.0, timeout=30) == ECA_NORMAL  # the arm in (l = 136: fine)
        assert put_status(prefix + "T1:L", 600.0, timeout=30) == ECA_PUTFAIL  # off the table with the arm in
        assert get(prefix + "t1_table:Refused") == 1
        assert get_str(prefix + "t1_table:Message").startswith(f"move of {prefix}T1:L to 600 refused")
        assert abs(get(prefix + "T1:L.RBV") - 136.2865) < 1e-3
        # a jog is not a target: the zone stops it on the way
        epics.caput(prefix + "T1:L.JVEL", 50, wait=True)
        epics.caput(prefix + "T1:L.JOGF", 1)
        assert wait_for(lambda: get(prefix + "t1_table:Stopped") == 1, 20)
        epics.caput(prefix + "T1:L.JOGF", 0)
        assert wait_for(lambda: get(prefix + "T1:L.DMOV") == 1, 10)
        assert 400 < get(prefix + "T1:L.RBV") < 500
        assert get(prefix + "t1_table:Inside") == 0


def test_sigterm_during_a_compound_move_stops_safely_and_exits_0(tmp_path, prefix):
    """The example has every automation part (the notifier's delivery thread among them): a stop
    signal mid-move takes the IOC's safe stop, exit code 0."""
    with running_snd(tmp_path, prefix) as srv:
        epics.caput(prefix + "E1", 4.0)  # about 6 s of motion
        assert wait_for(lambda: get(prefix + "E1.DMOV") == 0, 5)
        time.sleep(0.5)
        assert srv.stop() == 0
        assert "stopping" in srv.stderr()
        srv.start()  # running_config stops it again and checks it is alive
