"""Detectors through Channel Access (pyepics): the simulated energy-dispersive detector behind
synApps' mca record (examples/detectors/ioc.yaml), driven as users drive it: pyepics'
epics.devices.mca.MCA, the mca.db PVs, ERST with a put-callback that completes at the end of the
acquisition."""

import math
import time
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
        # MODE MCS: the simulated detector counts PHA only, so the put is refused and MODE stays
        assert put_status(p + "mca1.MODE", 1) != 1
        assert epics.caget(p + "mca1.MODE", as_string=True) == "PHA"
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


def running_four_elements(tmp_path, prefix):
    """The detectors example with four elements (element 4's preamp really has 2.1 mV/keV)."""
    cfg = (EXAMPLES / "detectors" / "ioc.yaml").read_text()
    cfg = cfg.replace("ioc: {name: DET}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    cfg = cfg.replace("    - name: mca1\n", "    - name: mca1\n      elements: 4\n      preamp_gains: [2.0, 2.0, 2.0, 2.1]\n")
    assert "elements: 4" in cfg
    return running_config(tmp_path, prefix, cfg, lambda: get(prefix + "mcaSum.NMAX") == 2048)


def peak_channel(spectrum, lo=600, hi=700):
    return max(range(lo, hi), key=lambda i: spectrum[i])


def test_four_elements_with_dxp_and_the_med_pvs(tmp_path, prefix):
    p = prefix
    with running_four_elements(tmp_path, p):
        dxps = [epics.devices.mca.DXP(p, mca=i) for i in range(1, 5)]
        mcas = [epics.devices.mca.MCA(p, mca=i) for i in range(1, 5)]
        assert dxps[0].get("PeakingTime") == 2.0
        assert dxps[3].get("PreampGain") == 2.0
        assert get(p + "dxp1:MCABinWidth_RBV") == 10.0  # eV per bin
        # dxpMED: a real-time preset for every element, EraseStart with a put-callback that
        # completes when they are all done (SetAcquireBusy -> AcquireBusy)
        assert put_status(p + "PresetMode", 1) == 1  # Real time
        assert put_status(p + "PresetReal", 1.5) == 1
        assert [m.get("PRTM") for m in mcas] == [1.5] * 4
        t0 = time.monotonic()
        assert put_status(p + "EraseStart", 1, timeout=30) == 1
        assert time.monotonic() - t0 > 1.0
        assert get(p + "Acquiring") == 0 and get(p + "AcquireBusy") == 0
        assert get(p + "ElapsedReal") == 1.5
        rate = 8000 + 1100 + 5000 + 700 + 200
        assert abs(get(p + "ElapsedLive") - 1.5 / (1 + rate * 2e-6)) < 1e-6
        spectra = [list(m.get("VAL")) for m in mcas]
        assert all(m.get("ERTM") == 1.5 for m in mcas)
        total = list(get(p + "mcaSum"))
        assert total == [sum(s[i] for s in spectra) for i in range(2048)]
        # element 4's Fe Ka sits 5 % high (2.1 / 2.0) until its PreampGain says 2.1
        assert peak_channel(spectra[0]) in range(635, 646)
        assert peak_channel(spectra[3], 650, 700) in range(667, 679)
        # the statistics: triggers per live second, events per real second
        icr, ocr = get(p + "dxp1:InputCountRate"), get(p + "dxp1:OutputCountRate")
        assert abs(icr - rate) < 0.1 * rate
        assert abs(ocr - sum(spectra[0]) / 1.5) < 1
        assert get(p + "dxp1:Events") == sum(spectra[0])
        assert get(p + "dxp1:Triggers") == get(p + "dxp1:Events")  # no thresholds: every event binned
        dxps[3].put("PreampGain", 2.1, wait=True)
        assert wait_for(lambda: get(p + "dxp4:PreampGain_RBV") == 2.1, 5)
        # a longer peaking time: narrower lines, more dead time
        dxps[0].put("PeakingTime", 8.0, wait=True)
        assert wait_for(lambda: get(p + "dxp1:PeakingTime_RBV") == 8.0, 5)
        assert put_status(p + "EraseStart", 1, timeout=30) == 1
        spectra = [list(m.get("VAL")) for m in mcas]
        assert peak_channel(spectra[3]) in range(635, 646)
        live = [m.get("ELTM") for m in mcas]
        assert abs(live[0] - 1.5 / (1 + rate * 2e-6 * 16.15 / 4.15)) < 1e-6
        assert abs(live[1] - 1.5 / (1 + rate * 2e-6)) < 1e-6
        # MaxEnergy: the bin width and the element's CALS follow
        dxps[1].put("MaxEnergy", 10.24, wait=True)
        assert wait_for(lambda: mcas[1].get("CALS") == 0.005, 5)
        assert get(p + "dxp2:MCABinWidth_RBV") == 5.0
        # refused: MaxEnergy below CALO; the record raises its alarm, nothing changes
        epics.caput(p + "dxp2:MaxEnergy", -3, wait=True)
        assert wait_for(lambda: epics.caget(p + "dxp2:MaxEnergy.SEVR") == 3, 5)
        assert get(p + "dxp2:MaxEnergy_RBV") == 10.24 and mcas[1].get("CALS") == 0.005


def test_the_sum_drives_every_element(tmp_path, prefix):
    p = prefix
    with running_four_elements(tmp_path, p):
        total = epics.devices.mca.MCA(p + "mcaSum")
        total.put("PRTM", 1.0, wait=True)
        assert put_status(p + "mcaSum.ERST", 1, timeout=30) == 1
        # every element acquired (their records followed) and the sum is theirs added
        assert wait_for(lambda: all(get(f"{p}mca{i}.ERTM") == 1.0 and get(f"{p}mca{i}.ACQG") == 0 for i in range(1, 5)), 5)
        spectra = [list(get(f"{p}mca{i}")) for i in range(1, 5)]
        assert list(total.get("VAL")) == [sum(s[i] for s in spectra) for i in range(2048)]
        # an ROI on the sum: Fe Ka of all four elements
        assert put_status(p + "mcaSum.R0LO", 600) == 1
        assert put_status(p + "mcaSum.R0HI", 700) == 1
        assert get(p + "mcaSum.R0") == sum(sum(s[600:701]) for s in spectra)


# ---------------------------------------------------------------------------------------------
# The quad electrometer (examples/bpm): quadEM's PVs over the simulated beam, a mirror move seen
# as PosY, and the fast loop that holds the beam
# ---------------------------------------------------------------------------------------------
def running_bpm(tmp_path, prefix):
    cfg = (EXAMPLES / "bpm" / "ioc.yaml").read_text()
    cfg = cfg.replace("ioc: {name: BPM}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    cfg = cfg.replace("plant: plant.yaml", f"plant: {EXAMPLES / 'bpm' / 'plant.yaml'}")
    cfg = cfg.replace("file: ../", f"file: {EXAMPLES}/")
    return running_config(tmp_path, prefix, cfg, lambda: get(prefix + "QE1:NumAcquired") > 0)


def test_quadem_position_follows_a_mirror_move_and_the_loop_holds_it(tmp_path, prefix):
    p = prefix + "QE1:"
    with running_bpm(tmp_path, prefix):
        assert epics.caget(p + "Geometry_RBV", as_string=True) == "Square"
        assert get(p + "SampleTime_RBV") == 0.001
        # average over 1 s: whole periods of the 7 Hz vibration
        assert put_status(p + "AveragingTime", 1.0) == 1
        assert wait_for(lambda: get(p + "NumAverage_RBV") == 1000, 5)
        assert abs(get(p + "SumAll:MeanValue_RBV") - 1.0) < 0.01  # uA, the whole spot

        def next_mean():
            n = get(p + "NumAcquired")
            assert wait_for(lambda: get(p + "NumAcquired") >= n + 2, 10)  # a whole average after the change
            return get(p + "PosY:MeanValue_RBV")
        y0 = next_mean()
        assert abs(y0) < 3, y0  # centred (the drift: 0.5 um/s)
        assert 3 < get(p + "PosY:SigmaValue_RBV") < 12  # the vibration: 10 um amplitude, 7 um rms
        # the mirror's jack up by h (DMOV may come within the axis's tolerance, the stage settles after): the spot
        # 25 h up, PosY = 125.33 erf(25 h / (0.1 sqrt 2)), 25 um for h = 1 um (within the piezo's +-45 um)
        motor = epics.Motor(prefix + "MirrorJack")
        assert put_status(prefix + "MirrorJack.CNEN", 1) == 1
        assert wait_for(lambda: get(prefix + "MirrorJack-EnaAct") == 1, 5)
        assert motor.move(0.001, wait=True, timeout=20) == 0
        y1 = next_mean()
        h = get(prefix + "MirrorJack.RBV")
        assert 0.0005 < h < 0.0015, h
        want = 125.33 * math.erf(25 * h / (0.1 * math.sqrt(2)))
        assert abs(y1 - y0 - want) < 5, (y0, y1, h, want)
        # the fast loop brings it back to 0 with the piezo, and takes out most of the vibration
        assert put_status(prefix + "epidFast1.FBON", 1) == 1
        assert put_status(prefix + "epidFast1.PROC", 1) == 1
        y2 = next_mean()
        assert abs(y2) < 2, y2
        assert get(p + "PosY:SigmaValue_RBV") < 3
        assert get(prefix + "epidFast1.OVAL") < -want / 5 / 2  # -want / 5 V: the piezo's 5 um/V
        # Single with a put-callback on Acquire (a busy record): done after one reading
        assert put_status(p + "Acquire", 0) == 1
        assert put_status(p + "AcquireMode", 2) == 1
        assert put_status(p + "AveragingTime", 0.2) == 1
        t0 = time.monotonic()
        assert put_status(p + "Acquire", 1, timeout=10) == 1
        assert time.monotonic() - t0 >= 0.15
        assert get(p + "NumAcquired") == 1 and get(p + "Acquire") == 0
        assert get(p + "NumAveraged_RBV") == 200


def test_quadem_time_series_shows_the_source_vibration(tmp_path, prefix):
    """quadEM's time-series plugin (TS:): 256 points of 10 ms means of PosY, acquired with a
    put-callback on TSAcquire (Fixed length), hold the source's 7 Hz vibration: the spectrum of
    TS:PosY:TimeSeries peaks at 7 Hz, its rms is the 10 um amplitude's 7.1 um."""
    import numpy as np
    ts = prefix + "QE1:TS:"
    with running_bpm(tmp_path, prefix):
        assert epics.caget(ts + "PosY:Name") == "PosY"
        assert put_status(ts + "TSNumPoints", 256) == 1
        assert put_status(ts + "TSAveragingTime", 0.01) == 1
        assert get(ts + "TSNumAverage") == 10
        assert epics.caget(ts + "TSAcquireMode", as_string=True) == "Fixed length"
        assert put_status(ts + "TSAcquire", 1, timeout=20) == 1  # done when 256 points are in
        assert get(ts + "TSAcquiring") == 0 and get(ts + "TSCurrentPoint") == 256
        y = np.asarray(epics.caget(ts + "PosY:TimeSeries", use_monitor=False))
        assert len(y) == 256
        t = np.asarray(epics.caget(ts + "TSTimeAxis", use_monitor=False))[:256]
        assert abs(t[1] - t[0] - 0.01) < 1e-9
        spectrum = np.abs(np.fft.rfft(y - y.mean()))
        freq = np.fft.rfftfreq(256, 0.01)
        assert abs(freq[spectrum.argmax()] - 7) < 0.5, freq[spectrum.argmax()]
        assert 5 < np.std(y) < 9
