"""The figures' script (docs/plots/make_plots.py) runs from a clean clone on its IOCs and makes
its four PNGs, with the loop's residual far below the open loop's and the rocking curve's centre
within 1 % of the width of the truth."""

import os
import re
import subprocess
from pathlib import Path

from conftest import BEAMCTL, require_binary

ROOT = Path(__file__).resolve().parents[2]


def test_the_figures_script_makes_its_pngs(tmp_path):
    require_binary()
    env = dict(os.environ, BEAMCTL_PLOTS_OUT=str(tmp_path))
    for k in ("EPICS_CA_ADDR_LIST", "EPICS_CA_AUTO_ADDR_LIST"):
        env.pop(k, None)
    out = subprocess.run(["/usr/bin/python3", str(ROOT / "docs/plots/make_plots.py"), BEAMCTL], env=env, capture_output=True,
                         text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    for name in ("feedback_residual.png", "camera_spot.png", "mca_spectrum.png", "rocking_curve.png"):
        png = tmp_path / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    m = re.search(r"off ([0-9.]+) um rms, on ([0-9.]+) um rms", out.stdout)
    assert m, out.stdout
    assert float(m.group(1)) > 4 * float(m.group(2)), out.stdout
    assert re.search(r"centroid 1[56][0-9]\.\d, 1[12][0-9]\.\d", out.stdout), out.stdout
    m = re.search(r"rocking_curve.png: centre [0-9.]+ truth [0-9.]+ error ([0-9.]+) % of the width", out.stdout)
    assert m and float(m.group(1)) < 1, out.stdout
