#!/usr/bin/python3
"""The figures of docs/detectors.md, docs/feedback.md and docs/automation.md, made from running IOCs with pyepics and
Debian's python3-matplotlib (Agg: no display needed):

  docs/img/feedback_residual.png  examples/bpm: QE1's PosY (10 ms averages) for 3 s with the fast
                                  loop off, then 3 s with it on
  docs/img/camera_spot.png        examples/bpm: one frame of the camera (image1:ArrayData) with
                                  Stats1's centroid and sigma
  docs/img/mca_spectrum.png       examples/detectors: a 2 s spectrum of mca1 with two ROIs
  docs/img/rocking_curve.png      examples/snd: the rocking curve of T1's first crystal
                                  (SND:rock_t1_th1), both passes and their Lorentzian fits, from
                                  the run's HDF5 file (Debian's python3-h5py)

  /usr/bin/python3 docs/plots/make_plots.py [BEAMCTL=build/release/beamctl]
(BEAMCTL_PLOTS_OUT=DIR writes them to DIR instead; tests/system/test_plots.py does.)
"""

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BEAMCTL = sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "build/release/beamctl")
OUT = Path(os.environ.get("BEAMCTL_PLOTS_OUT", ROOT / "docs/img"))  # the tests write elsewhere


def free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


PORT = free_port()
os.environ.update(EPICS_CA_ADDR_LIST=f"127.0.0.1:{PORT}", EPICS_CA_AUTO_ADDR_LIST="NO", EPICS_CA_MAX_ARRAY_BYTES="20000000")
import epics  # noqa: E402  (after the environment: libca reads it once)


class Ioc:
    """`beamctl run` of an example (its relative paths made absolute) on PORT."""

    def __init__(self, example, ready_pv):
        self.dir = tempfile.TemporaryDirectory()
        cfg = (ROOT / "examples" / example / "ioc.yaml").read_text()
        cfg = cfg.replace("plant: plant.yaml", f"plant: {ROOT / 'examples' / example / 'plant.yaml'}")
        cfg = cfg.replace("file: ../", f"file: {ROOT / 'examples'}/")
        cfg = cfg.replace("file: snd_", f"file: {ROOT / 'examples' / example}/snd_")
        path = Path(self.dir.name) / "ioc.yaml"
        path.write_text(cfg)
        env = dict(os.environ, EPICS_CAS_SERVER_PORT=str(PORT))
        self.proc = subprocess.Popen([BEAMCTL, "run", str(path), "--shell-socket", "none"], env=env,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        pv = epics.PV(ready_pv)
        if not pv.wait_for_connection(15):
            self.close()
            raise SystemExit(f"{example}: {ready_pv} does not connect")

    def close(self):
        self.proc.terminate()
        self.proc.wait(10)
        self.dir.cleanup()


def residual():
    ioc = Ioc("bpm", "BPM:QE1:PosY:MeanValue_RBV")
    try:
        epics.caput("BPM:QE1:AveragingTime", 0.01, wait=True)
        t, y = [], []
        pv = epics.PV("BPM:QE1:PosY:MeanValue_RBV", auto_monitor=True,
                      callback=lambda value=None, timestamp=None, **kw: (t.append(timestamp), y.append(value)))
        time.sleep(3.5)
        on = time.time()
        epics.caput("BPM:epidFast1.FBON", 1, wait=True)
        epics.caput("BPM:epidFast1.PROC", 1, wait=True)
        time.sleep(3.5)
        pv.clear_callbacks()
    finally:
        ioc.close()
    t = np.array(t) - on
    y = np.array(y)
    keep = (t > -3) & (t < 3)
    t, y = t[keep], y[keep]
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.plot(t, y, lw=0.8)
    ax.axvline(0, color="k", lw=0.6, ls="--")
    off, closed = y[t < 0], y[t > 0.3]
    ax.text(-2.9, ax.get_ylim()[1] * 0.8, f"loop off: {np.std(off):.1f} um rms", fontsize=8)
    ax.text(0.4, ax.get_ylim()[1] * 0.8, f"epidFast1 on: {np.std(closed):.1f} um rms", fontsize=8)
    ax.set_xlabel("time [s] (FBON at 0)")
    ax.set_ylabel("QE1 PosY [um], 10 ms means")
    ax.set_title("examples/bpm: 10 um at 7 Hz and 0.5 um/s of drift, held by the fast EPID loop", fontsize=9)
    fig.tight_layout()
    fig.savefig(OUT / "feedback_residual.png", dpi=110)
    print("feedback_residual.png:", f"off {np.std(off):.2f} um rms, on {np.std(closed):.2f} um rms")


def camera():
    ioc = Ioc("bpm", "BPM:cam1:Acquire")
    try:
        epics.caput("BPM:Stats1:CentroidThreshold", 100, wait=True)
        epics.caput("BPM:cam1:Acquire", 1, wait=True, timeout=10)
        nx, ny = int(epics.caget("BPM:image1:ArraySize0_RBV")), int(epics.caget("BPM:image1:ArraySize1_RBV"))
        frame = np.asarray(epics.caget("BPM:image1:ArrayData"))[: nx * ny].reshape(ny, nx)
        cx, cy = epics.caget("BPM:Stats1:CentroidX_RBV"), epics.caget("BPM:Stats1:CentroidY_RBV")
        sx, sy = epics.caget("BPM:Stats1:SigmaX_RBV"), epics.caget("BPM:Stats1:SigmaY_RBV")
    finally:
        ioc.close()
    fig, ax = plt.subplots(figsize=(6, 4.2))
    im = ax.imshow(frame, cmap="viridis", origin="upper")
    ax.plot([cx], [cy], "r+", ms=12)
    ax.add_patch(matplotlib.patches.Ellipse((cx, cy), 4 * sx, 4 * sy, fill=False, color="r", lw=0.8))
    fig.colorbar(im, ax=ax, label="counts (UInt16)")
    ax.set_title(f"BPM:image1:ArrayData (10 ms)\nStats1: centroid ({cx:.1f}, {cy:.1f}) px, sigma ({sx:.1f}, {sy:.1f}) px", fontsize=8)
    ax.set_xlabel("x [pixel, 10 um]")
    ax.set_ylabel("y [pixel]")
    fig.tight_layout()
    fig.savefig(OUT / "camera_spot.png", dpi=110)
    print("camera_spot.png:", f"centroid {cx:.1f}, {cy:.1f}")


def spectrum():
    ioc = Ioc("detectors", "DET:mca1.VAL")
    try:
        for n, lo, hi, name in ((0, 612, 668, "Fe Ka"), (1, 774, 836, "Cu Ka")):
            epics.caput(f"DET:mca1.R{n}LO", lo, wait=True)
            epics.caput(f"DET:mca1.R{n}HI", hi, wait=True)
            epics.caput(f"DET:mca1.R{n}NM", name, wait=True)
        epics.caput("DET:mca1.PRTM", 2.0, wait=True)
        epics.caput("DET:mca1EraseStart", 1, wait=True, timeout=20)
        epics.caput("DET:mca1Read", 1, wait=True)
        counts = np.asarray(epics.caget("DET:mca1.VAL", use_monitor=False))
        calo, cals = epics.caget("DET:mca1.CALO"), epics.caget("DET:mca1.CALS")
        rois = [(epics.caget(f"DET:mca1.R{n}LO"), epics.caget(f"DET:mca1.R{n}HI"), epics.caget(f"DET:mca1.R{n}NM"),
                 epics.caget(f"DET:mca1.R{n}")) for n in (0, 1)]
    finally:
        ioc.close()
    e = calo + cals * np.arange(len(counts))
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.semilogy(e, np.maximum(counts, 0.5), lw=0.7)
    for lo, hi, name, total in rois:
        ax.axvspan(calo + cals * lo, calo + cals * hi, alpha=0.2, color="orange")
        ax.text(calo + cals * lo, counts.max() * 1.5, f"{name}: {int(total)}", fontsize=7)
    ax.set_xlim(0, 12)
    ax.set_xlabel("energy [keV]")
    ax.set_ylabel("counts / channel")
    ax.set_title("DET:mca1, 2 s real-time preset, ROIs R0 and R1", fontsize=9)
    fig.tight_layout()
    fig.savefig(OUT / "mca_spectrum.png", dpi=110)
    print("mca_spectrum.png:", ", ".join(f"{r[2]} {int(r[3])}" for r in rois))


def rocking_curve():
    import h5py

    ioc = Ioc("snd", "SND:rock_t1_th1:Start")
    try:
        path = ioc.dir.name
        epics.caput("SND:rock_t1_th1:FilePath", np.frombuffer(path.encode() + b"\0", dtype=np.uint8), wait=True)
        epics.caput("SND:rock_t1_th1:Start", 1, wait=True, timeout=120)
        status = epics.caget("SND:rock_t1_th1:Status", as_string=True)
        truth = epics.caget("SND:Beam:ThB") + epics.caget("SND:Sim:T1:TH1:Offset")
        fwhm = epics.caget("SND:Sim:FWHM")
        file = bytes(epics.caget("SND:rock_t1_th1:File")).split(b"\0")[0].decode()
        with h5py.File(file, "r") as f:
            passes = []
            for name in ("rock_t1_th1_pass1", "rock_t1_th1_pass2"):
                g = f["entry"][name]
                passes.append((g["SND_T1_TH1"][:], g["signal"][:], g["fit"][:], dict(g.attrs)))
    finally:
        ioc.close()
    if status != "Done":
        raise SystemExit(f"rock_t1_th1 ended {status}")
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2), sharey=True)
    for k, (ax, (x, y, fit, a)) in enumerate(zip(axes, passes)):
        fine = np.linspace(x.min(), x.max(), 400)
        g = a["fit_width"] / 2
        ax.plot(x, y, ".", ms=4, label="T1:DH / DI")
        ax.plot(fine, a["fit_background"] + a["fit_amplitude"] / (1 + ((fine - a["fit_center"]) / g) ** 2), lw=0.9,
                label="Lorentzian fit")
        ax.axvline(truth, color="k", lw=0.6, ls="--", label="truth")
        ax.set_title(f"pass {k + 1}: {len(x)} points; centre {a['fit_center']:.5f} ± {a['fit_center_err']:.1e}\n"
                     f"FWHM {a['fit_width']:.5f}, reduced χ² {a['fit_reduced_chi2']:.2f}", fontsize=8)
        ax.set_xlabel("SND:T1:TH1 [deg]")
    axes[0].set_ylabel("downstream / upstream")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"examples/snd: SND:rock_t1_th1 (truth {truth:.5f} deg, FWHM {fwhm} deg)", fontsize=9)
    fig.tight_layout()
    fig.savefig(OUT / "rocking_curve.png", dpi=110)
    c = passes[1][3]["fit_center"]
    print("rocking_curve.png:", f"centre {c:.6f} truth {truth:.6f} error {abs(c - truth) / fwhm * 100:.3f} % of the width")


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    residual()
    camera()
    spectrum()
    rocking_curve()
