#!/usr/bin/python3
"""Plan overhead a point: seed 003's rocking curve of T1's first crystal (examples/snd: 41 + 31
points, two Lorentzian fits, moves to the centre) run by the IOC as the plan SND:rock_t1_th1, and
the same procedure as a pyepics script against the same IOC in the same run (caput wait=True to
each point, sleep(dwell), caget of both diagnostics, scipy's curve_fit between the passes, caput
to the centre). Both start from the same position and take the same points.
Reported a run: wall time, per point, and the overhead a point beyond motion and dwell:
  plan:   the IOC's own figure (SND:rock_t1_th1:Overhead: from the motor record's completion to the
          point's row, less the dwell; it includes the IOC loop's wake-ups)
  script: from caput(wait=True) returning to the next caput, less the dwell (sleep's overshoot,
          the two cagets, the bookkeeping); the put-callback's trip back to the client is in
          neither figure but is in the script's wall time.
Needs Debian's python3-scipy for the script's fits (a reference only, not a beamctl dependency).
    /usr/bin/python3 bench/plan_overhead.py [RUNS=3] [DWELL=0.05]"""

import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RUNS = int(sys.argv[1]) if len(sys.argv) > 1 else 3
DWELL = float(sys.argv[2]) if len(sys.argv) > 2 else 0.05
PASSES = ((0.1, 41), (0.03, 31))


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


port = free_port()
os.environ.update(EPICS_CA_ADDR_LIST="127.0.0.1", EPICS_CA_AUTO_ADDR_LIST="NO", EPICS_CA_SERVER_PORT=str(port),
                  EPICS_CAS_SERVER_PORT=str(port), EPICS_CAS_INTF_ADDR_LIST="127.0.0.1")
import epics  # noqa: E402  (after the environment)
from scipy.optimize import curve_fit  # noqa: E402


def lorentzian(x, x0, g, a, b):
    return b + a / (1 + ((x - x0) / g) ** 2)


def text(name):
    return bytes(epics.caget(name)).split(b"\0")[0].decode()


def put_text(name, s):
    epics.caput(name, np.frombuffer(s.encode() + b"\0", dtype=np.uint8), wait=True)


def script_rocking_curve(motor, down, up, start):
    """The rocking curve as a bluesky-less Python plan would run it: returns (wall s, points, overhead s a point)."""
    t_begin = time.perf_counter()
    center, overheads, n = start, [], 0
    t_done = None
    for rng, pts in PASSES:
        xs, ys = [], []
        for k in range(pts):
            target = center - rng / 2 + rng * k / (pts - 1)
            if t_done is not None:
                overheads.append(time.perf_counter() - t_done - DWELL)
            epics.caput(motor, target, wait=True, timeout=30)
            t_done = time.perf_counter()
            time.sleep(DWELL)
            d, u = epics.caget(down), epics.caget(up)
            xs.append(epics.caget(motor + ".RBV"))
            ys.append(d / u)
            n += 1
        xs, ys = np.array(xs), np.array(ys)
        p0 = (xs[np.argmax(ys)], rng / 10, ys.max() - ys.min(), ys.min())
        p, _ = curve_fit(lorentzian, xs, ys, p0=p0)
        center = p[0]
        overheads.append(time.perf_counter() - t_done - DWELL)  # the last point's read and the fit
        epics.caput(motor, center, wait=True, timeout=30)
        t_done = None
    return time.perf_counter() - t_begin, n, float(np.mean(overheads)), center


work = Path(tempfile.mkdtemp())
ioc = subprocess.Popen([str(ROOT / "build/release/beamctl"), "run", str(ROOT / "examples/snd/ioc.yaml")],
                       stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=work)
try:
    for line in ioc.stdout:  # the log, then "ready: ..."
        if line.startswith(b"ready:"):
            break
    else:
        raise SystemExit("the IOC did not start")
    threading.Thread(target=lambda: [None for _ in ioc.stdout], daemon=True).start()  # keep its log flowing
    P = "SND:rock_t1_th1:"
    motor, down, up = "SND:T1:TH1", "SND:T1:DH:I", "SND:DI:I"
    for pv in (P + "Start", motor, down, up):
        assert epics.PV(pv).wait_for_connection(5), pv
    start = epics.caget(motor + ".RBV")
    truth = epics.caget("SND:Beam:ThB") + epics.caget("SND:Sim:T1:TH1:Offset")
    put_text(P + "FilePath", str(work))
    put_text(P + "Args", f"dwell={DWELL}")
    print(f"rocking curve of {motor}: passes {PASSES}, dwell {DWELL} s, truth {truth:.6f} deg; {RUNS} runs each, alternating")
    for run in range(RUNS):
        epics.caput(motor, start, wait=True, timeout=30)
        t0 = time.perf_counter()
        epics.caput(P + "Start", 1, wait=True, timeout=300)
        wall = time.perf_counter() - t0
        n = sum(p for _, p in PASSES)
        assert epics.caget(P + "Status", as_string=True) == "Done", text(P + "Message")
        print(f"plan   run {run + 1}: {wall:6.2f} s, {1e3 * wall / n:6.1f} ms a point, overhead {epics.caget(P + 'Overhead'):6.3f} ms a point"
              f" (IOC), centre {epics.caget(P + 'Center'):.6f}")
        epics.caput(motor, start, wait=True, timeout=30)
        wall, n, over, centre = script_rocking_curve(motor, down, up, start)
        print(f"script run {run + 1}: {wall:6.2f} s, {1e3 * wall / n:6.1f} ms a point, overhead {1e3 * over:6.3f} ms a point"
              f" (client), centre {centre:.6f}")
finally:
    ioc.terminate()
    ioc.wait()
