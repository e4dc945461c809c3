"""The area detector through Channel Access (pyepics on the real libca): the simulated camera of
examples/bpm behind ADCore's PV sets (cam1:, image1:, HDF1:, Stats1:), driven as users drive it:
pyepics' AreaDetector device classes, Acquire with a put-callback, frames into an HDF5 file read
back with h5py, the statistics plugin following a mirror move, and an ophyd-style
stage / trigger / read / unstage sequence."""

import os
import subprocess
import time

import epics
import h5py
import numpy as np
from epics import ca
from epics.devices.ad_base import AD_Camera
from epics.devices.ad_fileplugin import AD_FilePlugin
from epics.devices.ad_image import AD_ImagePlugin

from conftest import BEAMCTL, connect, put_status, require_binary, wait_for
from test_detectors import EXAMPLES, running_bpm

ECA_PUTFAIL = 160


def get(name, **kw):
    return ca.get(connect(name), **kw)


def text(name):
    return epics.caget(name, as_string=True)


def test_pyepics_area_detector_classes_see_every_pv(tmp_path, prefix):
    p = prefix
    with running_bpm(tmp_path, p):
        cam, image, hdf = AD_Camera(p + "cam1:"), AD_ImagePlugin(p + "image1:"), AD_FilePlugin(p + "HDF1:")
        for dev in (cam, image, hdf):
            for attr in dev.attrs:
                pv = dev.PV(attr)
                assert pv.wait_for_connection(5), f"{pv.pvname} does not connect"
        assert cam.get("MaxSizeX_RBV") == 320 and cam.get("MaxSizeY_RBV") == 240
        assert cam.get("DataType_RBV", as_string=True) == "UInt16"
        assert cam.get("ImageMode_RBV", as_string=True) == "Single"
        assert cam.get("DetectorState_RBV", as_string=True) == "Idle"
        assert hdf.getTemplate() == "%s%s_%3.3d.h5"
        assert text(p + "HDF1:PluginType_RBV") == "NDFileHDF5"
        assert text(p + "Stats1:PluginType_RBV") == "NDPluginStats"


def test_a_single_image_with_a_put_callback_and_its_statistics(tmp_path, prefix):
    p = prefix
    with running_bpm(tmp_path, p):
        assert put_status(p + "Stats1:CentroidThreshold", 100) == 1  # above the dark level
        before = get(p + "cam1:ArrayCounter_RBV")
        # the put-callback completes when the frame is acquired and every plugin has it
        assert put_status(p + "cam1:Acquire", 1, timeout=10) == 1
        assert get(p + "cam1:Acquire") == 0 and get(p + "cam1:AcquireBusy") == 0
        assert text(p + "cam1:DetectorState_RBV") == "Idle"
        assert get(p + "cam1:ArrayCounter_RBV") == before + 1
        assert get(p + "cam1:NumImagesCounter_RBV") == 1
        assert get(p + "Stats1:ArrayCounter_RBV") == get(p + "image1:ArrayCounter_RBV") >= 1
        # the spot (0.3 x 0.1 mm sigma at the origin) on 10 um pixels: centre (159.5, 119.5)
        cx, cy = get(p + "Stats1:CentroidX_RBV"), get(p + "Stats1:CentroidY_RBV")
        assert abs(cx - 159.5) < 1.0, cx
        assert abs(cy - 119.5) < 2.0, cy  # the source vibrates 1 pixel and drifts
        assert abs(get(p + "Stats1:SigmaX_RBV") - 30) < 2
        assert abs(get(p + "Stats1:SigmaY_RBV") - 10) < 1.5
        assert 20000 < get(p + "Stats1:MaxValue_RBV") < 32000
        image = epics.caget(p + "image1:ArrayData")
        assert len(image) == 320 * 240
        frame = np.asarray(image).reshape(240, 320)
        assert frame.max() == get(p + "Stats1:MaxValue_RBV")
        assert abs(frame.sum() - get(p + "Stats1:Total_RBV")) < 1
        row, col = np.unravel_index(frame.argmax(), frame.shape)
        assert abs(col - 159.5) < 6 and abs(row - 119.5) < 4


def test_binning_and_region_and_refusals(tmp_path, prefix):
    p = prefix + "cam1:"
    with running_bpm(tmp_path, prefix):
        assert put_status(p + "BinX", 2) == 1
        assert put_status(p + "BinY", 2) == 1
        assert get(p + "ArraySizeX_RBV") == 160 and get(p + "ArraySizeY_RBV") == 120
        assert put_status(p + "MinX", 300) == 1
        assert get(p + "SizeX_RBV") == 20  # clipped to the sensor
        assert put_status(p + "MinX", 0) == 1
        assert put_status(p + "Acquire", 1, timeout=10) == 1
        assert get(prefix + "image1:ArraySize0_RBV") == 160
        assert get(prefix + "image1:ArraySize1_RBV") == 120
        assert abs(get(prefix + "Stats1:CentroidX_RBV") - 79.5) < 1.5
        # refused, nothing changed
        assert put_status(p + "DataType", 6) == ECA_PUTFAIL  # Int64: not made by this camera
        assert text(p + "DataType_RBV") == "UInt16"
        assert put_status(p + "ColorMode", 2) == ECA_PUTFAIL
        assert put_status(p + "AcquireTime", -1) == ECA_PUTFAIL
        assert get(p + "AcquireTime_RBV") == 0.01
        assert put_status(prefix + "HDF1:FileTemplate", "%s%s%n") == ECA_PUTFAIL
        assert put_status(prefix + "HDF1:FileTemplate", "%s%s%s_%d.h5") == ECA_PUTFAIL
        assert text(prefix + "HDF1:FileTemplate_RBV") == "%s%s_%3.3d.h5"
        assert text(prefix + "HDF1:FileWriteMode") == "Single"  # Capture is refused
        assert put_status(prefix + "HDF1:Capture", 1) == ECA_PUTFAIL
        # the plugins' NDArrayPort readbacks are the port's name, not a number
        assert text(prefix + "HDF1:NDArrayPort_RBV") == text(prefix + "HDF1:NDArrayPort") == "cam1"
        assert text(prefix + "image1:NDArrayPort_RBV") == "cam1"
        assert put_status(prefix + "HDF1:NDArrayPort", "cam1") == 1
        assert text(prefix + "HDF1:NDArrayPort_RBV") == "cam1"
        # ReadFile is refused and WriteMessage says why
        assert put_status(prefix + "HDF1:ReadFile", 1) == ECA_PUTFAIL
        msg = bytes(get(prefix + "HDF1:WriteMessage")).split(b"\0")[0].decode()
        assert "ReadFile" in msg and "refused" in msg, msg


def test_multiple_images_streamed_into_an_hdf5_file(tmp_path, prefix):
    p = prefix
    data = tmp_path / "data"
    data.mkdir()
    with running_bpm(tmp_path, p):
        epics.caput(p + "HDF1:FilePath", str(data), wait=True)
        assert text(p + "HDF1:FilePath_RBV") == str(data) + "/"
        assert get(p + "HDF1:FilePathExists_RBV") == 1
        epics.caput(p + "HDF1:FileName", "spot", wait=True)
        epics.caput(p + "HDF1:FileNumber", 7, wait=True)
        assert text(p + "HDF1:FileWriteMode") == "Single"  # ADCore's default
        epics.caput(p + "HDF1:FileWriteMode", "Stream", wait=True)
        epics.caput(p + "HDF1:NumCapture", 5, wait=True)
        epics.caput(p + "HDF1:Capture", 1)  # a busy record: done when 5 frames are in the file
        assert wait_for(lambda: get(p + "HDF1:Capture_RBV") == 1, 5)
        assert text(p + "HDF1:FullFileName_RBV") == f"{data}/spot_007.h5"
        assert get(p + "HDF1:FileNumber_RBV") == 8  # AutoIncrement: the next file's number
        epics.caput(p + "cam1:ImageMode", "Multiple", wait=True)
        epics.caput(p + "cam1:NumImages", 5, wait=True)
        first = get(p + "cam1:UniqueId_RBV") + 1
        assert put_status(p + "cam1:Acquire", 1, timeout=20) == 1
        assert get(p + "cam1:NumImagesCounter_RBV") == 5
        assert wait_for(lambda: get(p + "HDF1:Capture") == 0, 5)
        assert get(p + "HDF1:NumCaptured_RBV") == 5
        assert get(p + "HDF1:WriteStatus") == 0
        with h5py.File(data / "spot_007.h5", "r") as f:
            d = f["entry/data/data"]
            assert d.shape == (5, 240, 320) and d.dtype == np.uint16
            assert f["entry/instrument/detector/data"].attrs["NX_class"] == "SDS"
            ids = list(f["entry/instrument/NDAttributes/NDArrayUniqueId"][:])
            assert ids == list(range(first, first + 5))
            assert f["entry"].attrs["NX_class"] == "NXentry"
            last = d[4]
        # the last frame in the file is the last one the image plugin served
        served = np.asarray(epics.caget(p + "image1:ArrayData")).reshape(240, 320)
        assert (served == last).all()


def test_a_file_that_cannot_be_written_is_an_error_not_a_hang(tmp_path, prefix):
    p = prefix + "HDF1:"
    with running_bpm(tmp_path, prefix):
        epics.caput(p + "FilePath", str(tmp_path / "no" / "such" / "dir"), wait=True)
        assert get(p + "FilePathExists_RBV") == 0
        epics.caput(p + "NumCapture", 2, wait=True)
        epics.caput(p + "FileWriteMode", "Stream", wait=True)
        epics.caput(p + "Capture", 1)
        epics.caput(prefix + "cam1:ImageMode", "Multiple", wait=True)
        epics.caput(prefix + "cam1:NumImages", 2, wait=True)
        assert put_status(prefix + "cam1:Acquire", 1, timeout=20) == 1
        assert wait_for(lambda: get(p + "WriteStatus") == 1, 5)
        assert "no/such/dir" in text(p + "WriteMessage")
        assert wait_for(lambda: get(p + "Capture") == 0, 5)  # the capture ended (its callback too)
        assert not os.path.exists(tmp_path / "no")


def test_the_camera_sees_a_mirror_move(tmp_path, prefix):
    p = prefix
    with running_bpm(tmp_path, p):
        # exposures of two whole periods of the source's 7 Hz vibration (the blur averages it out),
        # the gain down so that the peak stays below saturation
        assert put_status(p + "cam1:AcquireTime", 2 / 7) == 1
        assert put_status(p + "cam1:Gain", 0.03) == 1
        assert put_status(p + "Stats1:CentroidThreshold", 100) == 1
        jack = epics.Motor(p + "MirrorJack")
        assert put_status(p + "MirrorJack.CNEN", 1) == 1
        assert wait_for(lambda: get(p + "MirrorJack-EnaAct") == 1, 5)

        def centroid_y():
            assert put_status(p + "cam1:Acquire", 1, timeout=10) == 1
            assert get(p + "Stats1:MaxValue_RBV") < 65535  # not saturated
            return get(p + "Stats1:CentroidY_RBV")
        h0, y0 = jack.get("RBV"), centroid_y()
        # 4 um of jack: the spot 100 um up, 10 pixels (rows count downwards); DMOV may come within
        # the axis's tolerance and the stage settles after: the expectation follows the readback
        assert jack.move(0.004, wait=True, timeout=30) == 0
        settled = []

        def still():  # the readback no longer moves (0.05 um in 0.3 s)
            settled.append(jack.get("RBV"))
            time.sleep(0.3)
            return abs(jack.get("RBV") - settled[-1]) < 5e-5
        assert wait_for(still, 10)
        h1 = jack.get("RBV")
        y1 = centroid_y()
        want = 25 * (h1 - h0) / 0.01
        assert 8 < want < 12
        assert abs((y0 - y1) - want) < 0.5, (y0, y1, want)


def test_an_ophyd_style_sequence(tmp_path, prefix):
    """What ophyd's SingleTrigger + HDF5 plugin do: stage (settings, Capture on), trigger (Acquire
    with a put-callback) and read (the statistics) three times, unstage (Capture off: the file is
    closed with the frames taken)."""
    p = prefix
    data = tmp_path / "frames"
    data.mkdir()
    with running_bpm(tmp_path, p):
        # stage
        staged = {
            "cam1:ImageMode": "Single", "cam1:AcquireTime": 0.02, "HDF1:FilePath": str(data), "HDF1:FileName": "scan",
            "HDF1:FileWriteMode": "Stream", "HDF1:NumCapture": 0, "HDF1:AutoIncrement": "Yes", "HDF1:FileNumber": 1,
        }
        for k, v in staged.items():
            assert epics.caput(p + k, v, wait=True) == 1, k
        epics.caput(p + "HDF1:Capture", 1)
        assert wait_for(lambda: get(p + "HDF1:Capture_RBV") == 1, 5)
        path = text(p + "HDF1:FullFileName_RBV")
        assert path == f"{data}/scan_001.h5"
        totals = []
        for _ in range(3):  # trigger, read
            assert put_status(p + "cam1:Acquire", 1, timeout=10) == 1
            totals.append(get(p + "Stats1:Total_RBV"))
        assert get(p + "HDF1:NumCaptured_RBV") == 3
        # unstage
        assert put_status(p + "HDF1:Capture", 0) == 1
        assert wait_for(lambda: get(p + "HDF1:Capture_RBV") == 0, 5)
        with h5py.File(path, "r") as f:
            frames = f["entry/data/data"][:]
        assert frames.shape == (3, 240, 320)
        assert [int(x.sum(dtype=np.int64)) for x in frames] == [int(t) for t in totals]
        # 20 ms exposures: twice the 10 ms default's signal over the dark
        assert abs(totals[0] - 2 * 5e9 * 0.01 - 320 * 240 * 10) < 0.02 * totals[0]


def test_check_and_run_refuse_a_camera_on_a_bus_without_a_beam(tmp_path):
    """`beamctl check` and `beamctl run` name the entry whose bus has no simulated beam."""
    require_binary()
    cfg = (EXAMPLES / "bpm" / "ioc.yaml").read_text()
    cfg = cfg.replace("plant: plant.yaml", f"plant: {EXAMPLES / 'bpm' / 'plant.yaml'}").replace("file: ../", f"file: {EXAMPLES}/")
    cfg = cfg.replace("acquire_period: 0.05}", "acquire_period: 0.05, bus: 3}")
    path = tmp_path / "ioc.yaml"
    path.write_text(cfg)
    line = next(i for i, l in enumerate(cfg.splitlines(), 1) if "bus: 3}" in l)
    want = f"{path}:{line}:7: area_detector cam1: bus 3 has no simulated beam in this IOC"
    out = subprocess.run([BEAMCTL, "check", str(path)], capture_output=True, text=True, timeout=30)
    assert out.returncode != 0
    assert want in out.stdout + out.stderr, out.stdout + out.stderr
    # an MCA alike (the sample under a beam that is not there)
    mca = cfg.replace("detectors:\n", "detectors:\n  mca:\n    - {name: mca1, bus: 5}\n")
    mca_path = tmp_path / "mca.yaml"
    mca_path.write_text(mca.replace("acquire_period: 0.05, bus: 3}", "acquire_period: 0.05}"))
    out2 = subprocess.run([BEAMCTL, "check", str(mca_path)], capture_output=True, text=True, timeout=30)
    assert out2.returncode != 0
    assert "mca mca1: bus 5 has no simulated beam in this IOC" in out2.stdout + out2.stderr, out2.stdout + out2.stderr
    env = dict(os.environ, EPICS_CAS_SERVER_PORT="0")
    out = subprocess.run([BEAMCTL, "run", str(path), "--shell-socket", "none"], capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode != 0
    assert want in out.stderr, out.stderr
