"""Detectors through Channel Access (pyepics): the simulated energy-dispersive detector behind
synApps' mca record (examples/detectors/ioc.yaml), driven as users drive it: pyepics'
epics.devices.mca.MCA, the mca.db PVs, ERST with a put-callback that completes at the end of the
acquisition."""

from pathlib import Path

import epics
import epics.devices.mca
from epics import ca

from conftest import connect, put_status, running_config, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def get(name, **kw):
    return ca.get(connect(name), **kw)


def running_example(tmp_path, prefix):
    cfg = (EXAMPLES / "detectors" / "ioc.yaml").read_text()
    cfg = cfg.replace("ioc: {name: DET}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    return running_config(tmp_path, prefix, cfg, lambda: get(prefix + "mca1.NMAX") == 2048)


def test_an_acquisition_with_a_real_time_preset(tmp_path, prefix):
    p = prefix
    with running_example(tmp_path, p):
        mca = epics.devices.mca.MCA(p, mca=1)
        assert mca.get("CALS") == 0.01 and mca.get("NUSE") == 2048
        assert put_status(p + "mca1.PRTM", 1.5) == 1
        # R0 over Fe Ka (6.404 keV = channel 640), R1 over Cu Ka (805), 4 sigma of the line either side
        for n, lo, hi, name in ((0, 612, 668, "Fe Ka"), (1, 774, 836, "Cu Ka")):
            assert put_status(f"{p}mca1.R{n}LO", lo) == 1
            assert put_status(f"{p}mca1.R{n}HI", hi) == 1
            assert put_status(f"{p}mca1.R{n}BG", 2) == 1
            epics.caput(f"{p}mca1.R{n}NM", name, wait=True)
        # EraseStart with a put-callback: done when the acquisition is
        assert put_status(p + "mca1.ERST", 1, timeout=30) == 1
        assert get(p + "mca1.ACQG") == 0
        assert get(p + "mca1.ERTM") == 1.5
        rate = 8000 + 1100 + 5000 + 700 + 200
        eltm = get(p + "mca1.ELTM")
        assert abs(eltm - 1.5 / (1 + rate * 2e-6)) < 1e-6
        assert abs(get(p + "mca1.DTIM") - 100 * (1 - 1 / (1 + rate * 2e-6))) < 1e-3
        spectrum = mca.get("VAL")
        assert len(spectrum) == 2048
        assert abs(sum(spectrum) - rate * eltm) < 5 * (rate * eltm) ** 0.5
        assert get(p + "mca1.R0") == sum(spectrum[612:669])
        assert get(p + "mca1.R1") == sum(spectrum[774:837])
        # nets: the lines' counts over their background, within Poisson statistics
        assert abs(get(p + "mca1.R0N") - 8000 * eltm) < 5 * (8000 * eltm) ** 0.5 + 10
        assert abs(get(p + "mca1.R1N") - 5000 * eltm) < 5 * (5000 * eltm) ** 0.5 + 10
        assert epics.caget(p + "mca1.R0NM") == "Fe Ka"
        assert max(range(2048), key=lambda i: spectrum[i]) in range(635, 646)


def test_the_mca_db_commands(tmp_path, prefix):
    p = prefix
    with running_example(tmp_path, p):
        assert put_status(p + "mca1.PRTM", 0) == 1
        # a put-callback on EraseStart would complete when the acquisition ends (mca.db's PP link
        # to ERST): with no preset that is at the Stop below, so no wait here
        epics.caput(p + "mca1EraseStart", 1)
        assert wait_for(lambda: get(p + "mca1.ACQG") == 1, 5)
        # the Read record reads the spectrum while acquiring, every second
        assert wait_for(lambda: get(p + "mca1.NORD") == 2048 and sum(get(p + "mca1")) > 0, 5)
        assert wait_for(lambda: get(p + "mca1.ERTM") > 0.5, 5)
        assert put_status(p + "mca1Stop", 1) == 1
        assert wait_for(lambda: get(p + "mca1.ACQG") == 0, 5)
        ertm = get(p + "mca1.ERTM")
        total = sum(get(p + "mca1"))
        assert total > 0
        assert put_status(p + "mca1Erase", 1) == 1
        assert wait_for(lambda: get(p + "mca1.NORD") == 0, 5)
        assert get(p + "mca1.ERTM") == 0 or get(p + "mca1.ERTM") <= ertm
