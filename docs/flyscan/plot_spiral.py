#!/usr/bin/python3
"""The captured trigger positions of the spiral fly scan (examples/flyscan/ioc.yaml) on the spiral,
as seed 000's figures 3 and 4: the stage path (x, y) with the time-based (black squares) and
distance-based (red dots) triggers, and the arc length against time.
    /usr/bin/python3 docs/flyscan/plot_spiral.py FILE.h5 [OUT.png]"""

import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

src = sys.argv[1]
out = sys.argv[2] if len(sys.argv) > 2 else "spiral_triggers.png"
with h5py.File(src, "r") as f:
    d = f["entry/data"]
    x, y, arc, t = d["x"][()], d["y"][()], d["arc"][()], d["t"][()]
    dist, timed = d["distance_trigger"][()] == 1, d["time_trigger"][()] == 1
t = t - t[0]
# the spiral itself (seed eqs 21-23: r = a e^(b θ), origin at the stage's start)
a, b = 1.0, 0.2
theta = np.linspace(0, np.log1p(arc.max() * b / (a * np.sqrt(1 + b * b))) / b, 500)
r = a * np.exp(b * theta)
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 5))
ax1.plot(-1 + r * np.cos(theta), r * np.sin(theta), color="0.7", lw=1, label="spiral")
ax1.plot(x[timed], y[timed], "ks", ms=5, mfc="none", label="time-based (every 1.2 s)")
ax1.plot(x[dist], y[dist], "r.", ms=6, label="distance-based (every 0.8 mm)")
ax1.set_aspect("equal")
ax1.set_xlabel("x [mm]")
ax1.set_ylabel("y [mm]")
ax1.legend(loc="lower left", fontsize=8)
ax1.set_title("captured trigger positions on the log spiral")
ax2.plot(t[timed], arc[timed], "ks", ms=5, mfc="none", label="time-based")
ax2.plot(t[dist], arc[dist], "r.", ms=6, label="distance-based")
ax2.set_xlabel("t [s] since the first trigger")
ax2.set_ylabel("arc length [mm]")
ax2.legend(loc="upper left", fontsize=8)
ax2.set_title("arc length at the triggers")
fig.suptitle(f"{src.split('/')[-1]}: {dist.sum()} distance rows, {timed.sum()} time rows")
fig.tight_layout()
fig.savefig(out, dpi=90)
print(f"{out}: {dist.sum()} distance-based and {timed.sum()} time-based triggers")
