"""Plans (docs/automation.md) with a real EPICS client, on the split-and-delay example (examples/snd,
seed 003) and its simulated beam: the rocking curve of T1's first crystal finds the true centre
within 1 % of the crystal's width and leaves the crystal there; its HDF5/NeXus file reads back with
h5py; a fit without a peak puts the crystal back, latches the primary state machine and an email
and a webhook arrive; `beamctl plan run` starts, follows and aborts a plan; pause holds a scan and
resume finishes it; the seed's whole alignment procedure aligns every crystal."""

import ctypes
import signal
import subprocess
import time

import h5py
import numpy as np

import epics

from conftest import _put_done, BEAMCTL, DEFAULT_SIGINT, ECA_NORMAL, ECA_PUTFAIL, connect, put_status, running_config, wait_for
from test_automation import MailAndHooks, get, get_str, snd_config

CRYSTALS = ("T1:TH1", "T1:TH2", "T4:TH2", "T4:TH1", "T2:TH", "T3:TH")


def running_snd(tmp_path, prefix, srv=None):
    cfg = snd_config(prefix, srv.smtp_port, srv.http_port) if srv else snd_config(prefix)
    return running_config(tmp_path, prefix, cfg, lambda: get_str(prefix + "rock_t1_th1:Status") == "Idle",
                          timeout=20)


def set_text(name, text, status=ECA_NORMAL):
    """A CHAR waveform's text, put with a callback (DBR_CHAR): the status the server replied."""
    chid = connect(name)
    raw = text.encode() + b"\0"
    data = (ctypes.c_char * len(raw)).from_buffer_copy(raw)
    got = []
    assert epics.ca.libca.ca_array_put_callback(4, len(raw), chid, data, _put_done, ctypes.py_object(got)) == ECA_NORMAL
    epics.ca.flush_io()
    assert wait_for(lambda: got, 5)
    assert got[0] == status, (name, text, got[0])


def text(name):
    return bytes(get(name)).split(b"\0")[0].decode()


def truth(prefix, crystal):
    return get(prefix + "Beam:ThB") + get(prefix + "Sim:" + crystal + ":Offset")


def test_the_rocking_curve_finds_the_true_centre_within_1_percent_of_the_width(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        p = prefix + "rock_t1_th1:"
        set_text(p + "FilePath", str(tmp_path))
        start = get(prefix + "T1:TH1.RBV")
        true_centre, fwhm = truth(prefix, "T1:TH1"), get(prefix + "Sim:FWHM")
        assert abs(start - true_centre) > 0.5 * fwhm  # off the peak to begin with
        assert put_status(p + "Start", 1, timeout=120) == ECA_NORMAL  # the put-callback ends with the run
        assert get_str(p + "Status") == "Done"
        assert text(p + "Message") == "done"
        assert abs(get(p + "Center") - true_centre) < 0.01 * fwhm, (get(p + "Center"), true_centre)
        assert abs(get(p + "Width") - fwhm) < 0.02 * fwhm
        assert get(p + "FitOk") == 1 and get(p + "RedChi2") < 5 and get(p + "RSquared") > 0.99
        assert abs(get(prefix + "T1:TH1.RBV") - true_centre) <= max(0.01 * fwhm, get(prefix + "T1:TH1.MRES"))
        assert len(get(p + "X")) == 31 and len(get(p + "Fit")) == 31  # the last pass, live
        assert get(p + "Progress") == 100
        # the run's file
        path = text(p + "File")
        assert path.startswith(str(tmp_path) + "/rock_t1_th1_") and path.endswith("_1.h5")
        with h5py.File(path, "r") as f:
            entry = f["entry"]
            assert f.attrs["default"] == "entry" and entry.attrs["NX_class"] == "NXentry"
            assert entry.attrs["plan"] == "rock_t1_th1" and entry.attrs["status"] == "Done"
            assert entry.attrs["args"] == "dwell=0.05"
            p1, p2 = entry["rock_t1_th1_pass1"], entry["rock_t1_th1_pass2"]
            assert p1.attrs["NX_class"] == "NXdata" and p1.attrs["signal"] == "signal" and p1.attrs["axes"] == "SND_T1_TH1".replace(
                "SND_", prefix.replace(":", "_"))
            assert len(p1["signal"]) == 41 and len(p2["signal"]) == 31
            assert p2["down"].attrs["source"] == prefix + "T1:DH:I"
            np.testing.assert_allclose(p2["signal"][:], p2["down"][:] / p2["up"][:], rtol=1e-12)
            assert p2.attrs["fit_model"] == "lorentzian" and p2.attrs["fit_check"] == "good"
            assert abs(p2.attrs["fit_center"] - get(p + "Center")) < 1e-9
            x = p2[prefix.replace(":", "_") + "T1_TH1"][:]
            assert x.min() < true_centre < x.max()


def test_a_fit_without_a_peak_puts_the_crystal_back_latches_and_notifies(tmp_path, prefix):
    srv = MailAndHooks()
    try:
        with running_snd(tmp_path, prefix, srv):
            p = prefix + "rock_t1_th1:"
            set_text(p + "FilePath", str(tmp_path))
            assert put_status(prefix + "Sim:T1:TH1:Offset", 1.0) == ECA_NORMAL  # the peak is far outside the scan
            start = get(prefix + "T1:TH1.RBV")
            assert put_status(p + "Start", 1, timeout=120) == ECA_PUTFAIL
            assert get_str(p + "Status") == "Failed"
            assert get(p + "FitOk") == 0
            msg = text(p + "Message")
            assert "pass 1: fit refused" in msg and "is back at" in msg, msg
            assert abs(get(prefix + "T1:TH1.RBV") - start) < 2e-4  # back where it started
            assert get_str(prefix + "snd:State") == "error_latch"
            assert "plan rock_t1_th1 failed" in text(prefix + "snd:Error")
            assert wait_for(lambda: srv.mails and srv.posts, 10), (srv.mails, srv.posts)
            content = srv.mails[0][2]
            assert "Subject: [beamctl] state machine snd latched" in content
            assert "fit refused" in content
            assert "plan rock_t1_th1 failed" in srv.posts[0][2]
            with h5py.File(text(p + "File"), "r") as f:  # the failed run's data is kept
                assert f["entry"].attrs["status"] == "Failed"
                assert f["entry/rock_t1_th1_pass1"].attrs["fit_check"] != "good"
            # a latched machine still lets an operator acknowledge and run again once the beam is back
            assert put_status(prefix + "snd:Ack", 1) == ECA_NORMAL
            assert put_status(prefix + "Sim:T1:TH1:Offset", 0.012) == ECA_NORMAL
            assert put_status(p + "Start", 1, timeout=120) == ECA_NORMAL
    finally:
        srv.close()


def plan_cli(cfg, *args, timeout=120):
    return subprocess.run([str(BEAMCTL), "plan", "run", str(cfg), *args], capture_output=True, text=True, timeout=timeout)


def test_beamctl_plan_run_starts_follows_and_reports_and_ctrl_c_aborts(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        cfg = tmp_path / "ioc.yaml"
        set_text(prefix + "th1_scan:FilePath", str(tmp_path))
        set_text(prefix + "rock_t1_th1:FilePath", str(tmp_path))
        r = plan_cli(cfg, "rock_t1_th1", "dwell=0.02")
        assert r.returncode == 0, (r.stdout, r.stderr)
        assert "rock_t1_th1: run 1 started: dwell=0.02" in r.stdout
        assert "rock_t1_th1: pass 2/2: scanning" in r.stdout
        assert "rock_t1_th1: Done" in r.stdout
        assert "rock_t1_th1: centre " in r.stdout and f"rock_t1_th1: file {tmp_path}/rock_t1_th1_" in r.stdout
        # arguments are checked before anything moves
        r = plan_cli(cfg, "rock_t1_th1", "dwel=1")
        assert r.returncode == 2 and "'dwel' is not an argument of the plan (it takes dwell)" in r.stderr, r.stderr
        r = plan_cli(cfg, "nope")
        assert r.returncode == 2 and "no plan 'nope'" in r.stderr
        r = subprocess.run([str(BEAMCTL), "plan", "list", str(cfg)], capture_output=True, text=True, timeout=30)
        assert r.returncode == 0 and "th1_scan (scan): T1 crystal 1 around where it is" in r.stdout
        # Ctrl-C aborts the run: the motor stops, the plan says Aborted, the exit code says so
        # (SIGINT at its default disposition, as at a terminal, however pytest was started)
        start = get(prefix + "T1:TH1.RBV")
        proc = subprocess.Popen(DEFAULT_SIGINT + [str(BEAMCTL), "plan", "run", str(cfg), "th1_scan", "n=101"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert wait_for(lambda: get(prefix + "th1_scan:Point") >= 3, 30)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
        assert proc.returncode == 1, (out, err)
        assert "aborting" in err and "th1_scan: Aborted" in out
        assert get_str(prefix + "th1_scan:Status") == "Aborted"
        assert get(prefix + "th1_scan:Point") < 101
        time.sleep(0.3)
        assert get(prefix + "T1:TH1.DMOV") == 1
        assert abs(get(prefix + "T1:TH1.RBV") - start) < 0.06  # stopped inside the scan, not returned


def test_pause_holds_a_scan_and_resume_finishes_it(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        p = prefix + "th1_scan:"
        set_text(p + "FilePath", "")  # no file
        set_text(p + "Args", "n=21 width=0.02")
        start = get(prefix + "T1:TH1.RBV")
        epics.caput(p + "Start", 1)  # no wait: the run goes on
        assert wait_for(lambda: get(p + "Point") >= 2, 20)
        assert put_status(p + "Pause", 1) == ECA_NORMAL
        assert wait_for(lambda: get_str(p + "Status") == "Paused", 10)
        held = get(p + "Point")
        time.sleep(1.0)
        assert get(p + "Point") == held and get_str(p + "Status") == "Paused"
        assert put_status(p + "Start", 1) == ECA_PUTFAIL  # one run at a time
        assert put_status(p + "Resume", 1) == ECA_NORMAL
        assert wait_for(lambda: get_str(p + "Status") == "Done", 30)
        assert get(p + "Point") == 21
        x, y = get(p + "X"), get(p + "Y")
        assert len(x) == 21 and len(y) == 21
        assert abs(x[0] - (start - 0.01)) < 2e-4 and abs(x[-1] - (start + 0.01)) < 2e-4
        assert abs(get(prefix + "T1:TH1.RBV") - start) < 2e-4  # relative: back at the start
        assert text(p + "File") == ""


def test_the_seeds_alignment_procedure_aligns_every_crystal(tmp_path, prefix):
    with running_snd(tmp_path, prefix):
        p = prefix + "align:"
        set_text(p + "FilePath", str(tmp_path))
        fwhm = get(prefix + "Sim:FWHM")
        assert put_status(p + "Start", 1, timeout=300) == ECA_NORMAL, text(p + "Message")
        assert get_str(p + "Status") == "Done"
        for c in CRYSTALS:
            assert abs(get(prefix + c + ".RBV") - truth(prefix, c)) <= max(0.01 * fwhm, 1e-4), c
            assert get_str(prefix + "rock_" + c.lower().replace(":", "_") + ":Status") == "Done", c
        # t1.y1 splits the beam in half; t1.y2, t4.y1, t4.y2 followed it
        edge = get(prefix + "Sim:T1:Y1:Edge")
        assert abs(get(prefix + "T1:Y1.RBV") - edge) < 0.005
        for m in ("T1:Y2", "T4:Y1", "T4:Y2"):
            assert abs(get(prefix + m + ".RBV") - get(prefix + "T1:Y1.RBV")) < 2e-3, m
        with h5py.File(text(p + "File"), "r") as f:
            scans = [k for k in f["entry"] if k.startswith("s")]
            assert "s2_split_t1_y1_pass1" in scans and "s12_rock_t3_th_pass2" in scans, scans
            assert f["entry"].attrs["status"] == "Done"


def test_sigterm_during_a_plan_aborts_it_writes_its_file_and_exits_0(tmp_path, prefix):
    with running_snd(tmp_path, prefix) as srv:
        p = prefix + "th1_scan:"
        set_text(p + "FilePath", str(tmp_path))
        epics.caput(p + "Start", 1)
        assert wait_for(lambda: get(p + "Point") >= 3, 20)
        assert srv.stop() == 0
        files = list(tmp_path.glob("th1_scan_*.h5"))
        assert len(files) == 1, files
        with h5py.File(files[0], "r") as f:
            assert f["entry"].attrs["status"] == "Aborted"
            assert f["entry"].attrs["message"] == "aborted: the IOC is stopping"
            assert len(f["entry/th1_scan/signal"]) >= 3
        srv.start()  # running_config stops it again and checks it is alive


def test_a_plan_scans_another_iocs_motor_and_reads_its_detector_through_ca(tmp_path, prefix):
    """IOC A (beamctl softioc) serves a motor record and a detector following it; IOC B's plan
    scans and aligns them through its Channel Access client."""
    from conftest import IocServer, RunServer, acquire_port, forget_pvs, release_port, require_binary
    require_binary()
    a_prefix = prefix + "A:"
    (tmp_path / "a.db").write_text(
        'record(motor, "$(P)m") { field(DTYP, "Sim Motor") field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "5")'
        ' field(ACCL, "0.05") field(DLLM, "-10") field(DHLM, "10") }\n'
        'record(calc, "$(P)det") { field(INPA, "$(P)m.RBV CP") field(CALC, "10+100/(1+((A-1.5)/0.1)^2)") }\n')
    a_port = acquire_port()
    a = IocServer(tmp_path, [tmp_path / "a.db"], a_port, macros=f"P={a_prefix}", name="a").start()
    b_port = None
    try:
        cfg = f"""ioc: {{name: B, prefix: "{prefix}"}}
plans:
  - {{name: s, type: scan, axes: [{{motor: "{a_prefix}m", start: 0, stop: 2}}], points: 11, detectors: {{d: "{a_prefix}det"}},
     directory: "{tmp_path}"}}
  - {{name: a, type: align, motor: "{a_prefix}m", detectors: {{d: "{a_prefix}det"}}, passes: [{{range: 1.5, points: 31}}],
     min_r_squared: 0.99, directory: ""}}
"""
        (tmp_path / "b.yaml").write_text(cfg)
        b_port = acquire_port()
        b = RunServer(tmp_path, tmp_path / "b.yaml", b_port)
        b.extra_env = {"EPICS_CA_ADDR_LIST": f"127.0.0.1:{a_port}", "EPICS_CA_AUTO_ADDR_LIST": "NO"}
        b.start()
        try:
            assert put_status(prefix + "s:Start", 1, timeout=60) == ECA_NORMAL, text(prefix + "s:Message")
            y = get(prefix + "s:Y")
            want = [10 + 100 / (1 + ((0.2 * k - 1.5) / 0.1) ** 2) for k in range(11)]
            assert len(y) == 11 and max(abs(y - np.array(want))) < 0.5, (y, want)  # read after each arrival
            assert abs(get(a_prefix + "m.RBV") - 2) < 2e-3
            assert put_status(prefix + "a:Start", 1, timeout=60) == ECA_NORMAL, text(prefix + "a:Message")
            assert abs(get(prefix + "a:Center") - 1.5) < 0.002  # 1 % of the FWHM (0.2)
            assert abs(get(a_prefix + "m.RBV") - 1.5) < 2e-3
        finally:
            b.stop()
            b.kill()
    finally:
        a.stop()
        a.kill()
        forget_pvs(prefix)
        release_port(a_port)
        if b_port:
            release_port(b_port)


def test_the_primary_machines_auto_alignment_runs_the_procedure_and_a_failure_latches(tmp_path, prefix):
    """Seed 003: "transitioning to the auto-alignment begins execution of the alignment procedure";
    the transition's step is the plan's Start with a put-callback, so a failed alignment fails it."""
    from test_automation import wait_state
    with running_snd(tmp_path, prefix):
        fsm, bearing = prefix + "snd:", prefix + "bearing_t1:"
        set_text(prefix + "align:FilePath", "")
        for state in ("landed", "flying"):
            assert put_status(bearing + "Request", state) == ECA_NORMAL
            assert wait_state(prefix, "bearing_t1", state)
        for state in ("normal_operation", "online_calibration"):
            assert put_status(fsm + "Request", state) == ECA_NORMAL
            assert wait_state(prefix, "snd", state)
        assert put_status(prefix + "Sim:T4:TH2:Offset", 1.0) == ECA_NORMAL  # t4.th2's peak far away: its rocking curve fails
        assert put_status(fsm + "Request", "auto_alignment") == ECA_NORMAL
        assert wait_for(lambda: get_str(prefix + "align:Status") == "Running", 5)
        assert get(fsm + "Busy") == 1 and get_str(fsm + "Transition") == "auto_align"
        assert wait_for(lambda: get_str(prefix + "align:Status") == "Failed", 120)
        assert wait_state(prefix, "snd", "error_latch")
        error = text(fsm + "Error")
        assert "plan align failed" in error and "rock_t4_th2" in error and "fit refused" in error, error
        for done in ("split_t1_y1", "rock_t1_th1", "rock_t1_th2"):  # the steps before it had run
            assert get_str(prefix + done + ":Status") == "Done", done
        assert get_str(prefix + "rock_t4_th2:Status") == "Failed"
        assert get_str(prefix + "rock_t4_th1:Status") == "Idle"  # never reached
