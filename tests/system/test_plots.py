"""The figures' script (docs/plots/make_plots.py) runs from a clean clone on its IOCs and makes
its three PNGs, with the loop's residual far below the open loop's."""

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
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    for name in ("feedback_residual.png", "camera_spot.png", "mca_spectrum.png"):
        png = tmp_path / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    m = re.search(r"off ([0-9.]+) um rms, on ([0-9.]+) um rms", out.stdout)
    assert m, out.stdout
    assert float(m.group(1)) > 4 * float(m.group(2)), out.stdout
    assert re.search(r"centroid 1[56][0-9]\.\d, 1[12][0-9]\.\d", out.stdout), out.stdout
