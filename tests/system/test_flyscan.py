"""Fly scans through Channel Access (pyepics) on the shipped example (examples/flyscan/ioc.yaml):
arm a capture, enable the distance- and time-based PCOMP blocks, move the log-spiral arc axis,
read the counters, watch the file grow with a SWMR reader, disarm, and open the HDF5/NeXus file
with h5py: one row per trigger, the arc at each distance trigger within one cycle of its point.
And examples/flyscan/timestamped.yaml: the same points on an EL2808 and on a DC-timestamped EL2252,
both latched by an EL1252."""

import time
from pathlib import Path

import epics
import h5py
import numpy as np
from epics import ca

from conftest import ECA_NORMAL, ECA_PUTFAIL, RunServer, acquire_port, connect, forget_pvs, put_status, release_port, require_binary, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def start(tmp_path, prefix, example="ioc.yaml", before_pcomp="", before_plcs=""):
    text = (EXAMPLES / "flyscan" / example).read_text()
    text = text.replace("\npcomp:\n", "\n" + before_pcomp + "pcomp:\n", 1)
    if before_plcs:  # ends with "plcs:\n" and entries of its own, before the example's
        text = text.replace("\nplcs:\n", "\n" + before_plcs, 1)
    assert "ioc: {name: FLY}" in text
    text = text.replace("ioc: {name: FLY}", f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}')
    text = text.replace("file: ../", f"file: {EXAMPLES}/").replace("include: [../", f"include: [{EXAMPLES}/")
    text = text.replace("plant: timestamped_plant.yaml", f"plant: {EXAMPLES}/flyscan/timestamped_plant.yaml")
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(text)
    port = acquire_port()
    srv = RunServer(tmp_path, cfg, port)
    srv.start()
    return srv, port


def get(name):
    return ca.get(connect(name))


def put(name, value):
    assert put_status(name, value) == ECA_NORMAL, name


def text(name):
    return epics.caget(name, as_string=True, timeout=5)


def test_fly_scan_on_the_spiral_writes_a_nexus_file(tmp_path, prefix):
    require_binary()
    srv, port = start(tmp_path, prefix)
    try:
        p = prefix
        data = tmp_path / "data"
        data.mkdir()
        epics.caput(p + "PCAP:FILE_PATH", str(data), wait=True)
        epics.caput(p + "PCAP:FILE_NAME", "spiral_%03d.h5", wait=True)
        assert text(p + "PCAP:FILE_PATH") == str(data)
        assert get(p + "PCOMP1:STEP") == 0.8
        assert text(p + "PCOMP1:INP") == "ax3.enc.actpos"
        put(p + "PCAP:ARM", 1)
        assert wait_for(lambda: get(p + "PCAP:ACTIVE") == 1, 5)
        assert put_status(p + "PCAP:ARM", 1) == ECA_PUTFAIL  # refused while a capture runs
        put(p + "PCOMP1:ENABLE", 1)
        put(p + "PCOMP2:ENABLE", 1)
        assert wait_for(lambda: get(p + "PCOMP1:STATE") == 3, 5)  # WAIT_RISING: below START
        # 3.3 mm of arc at 1 mm/s (ramps of 2 s): pulses at 0.8, 1.6, 2.4, 3.2 mm
        # A slot the engine misses (a late wake-up on a loaded VM) lets the stage move on for that
        # slot as real mechanics would: the bounds below allow for the slots missed during the scan.
        missed_before = get(p + "m0-ThdMissedCycles")
        motor = epics.Motor(p + "SpiralL")
        assert motor.move(3.3, wait=False) in (0, 1)  # 1: MOVN was already seen
        assert wait_for(lambda: get(p + "PCOMP1:PRODUCED") >= 2, 20)
        # the file grows while the scan runs: a SWMR reader sees the rows flushed so far
        path = data / "spiral_001.h5"
        assert text(p + "PCAP:FULL_FILE_NAME") == str(path)

        def rows_seen():
            with h5py.File(path, "r", libver="latest", swmr=True) as f:
                return f["entry/data/arc"].shape[0]
        assert wait_for(lambda: rows_seen() >= 2, 5)
        assert wait_for(lambda: get(p + "SpiralL.DMOV") == 1 and get(p + "SpiralL.MOVN") == 0, 30)
        assert abs(get(p + "SpiralL.RBV") - 3.3) < 0.01
        missed = get(p + "m0-ThdMissedCycles") - missed_before
        assert missed >= 0
        assert get(p + "PCOMP1:PRODUCED") == 4
        assert get(p + "PCOMP1:HEALTH") == 0
        captured = get(p + "PCAP:ROWS_CAPTURED")
        assert captured >= 4 + 1
        put(p + "PCAP:DISARM", 1)
        assert wait_for(lambda: get(p + "PCAP:ACTIVE") == 0 and get(p + "PCAP:FILES") == 1, 10)
        assert get(p + "PCAP:ROWS_WRITTEN") == captured
        assert get(p + "PCAP:ROWS_DROPPED") == 0
        assert get(p + "PCAP:ERROR") == 0, text(p + "PCAP:STATUS")
        assert text(p + "PCAP:STATUS").startswith("wrote %d rows to " % captured)
        last = epics.caget(p + "PCAP:LAST:arc", timeout=5)

        with h5py.File(path, "r") as f:
            entry = f["entry"]
            assert entry.attrs["NX_class"] in (b"NXentry", "NXentry")
            d = entry["data"]
            assert d.attrs["NX_class"] in (b"NXdata", "NXdata")
            arc = d["arc"][()]
            assert len(arc) == captured
            assert d["arc"].attrs["units"] in (b"mm", "mm")
            assert d["arc"].attrs["source"] in (b"ax3.enc.actpos", "ax3.enc.actpos")
            fired = d["distance_trigger"][()] == 1
            points = arc[fired]
            assert len(points) == 4
            # each distance row: the arc the cycle saw, at or past its point by less than a cycle's
            # move (1 um at 1 mm/s and 1 kHz), or by the slots missed as well when there were any
            # (after a miss the PID catches up: half a slot's move more)
            slack = 0.0011 if missed == 0 else 0.001 * (missed + 1.5)
            for k, x in enumerate(points):
                ideal = 0.8 * (k + 1)
                assert ideal - 1e-9 <= x < ideal + slack, (k, x, missed)
            # the time-based rows: 1.2 s apart (the engine clock of the cycle), a missed slot late
            t = d["t"][()][d["time_trigger"][()] == 1]
            assert len(t) >= 3
            assert np.all(np.abs(np.diff(t) - 1.2) <= 1e-6 + 0.001 * missed), (np.diff(t), missed)
            assert np.all(np.diff(d["cycle"][()]) > 0)
            assert np.allclose(last[:len(arc)], arc)
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


def test_bad_puts_are_refused_and_change_nothing(tmp_path, prefix):
    require_binary()
    srv, port = start(tmp_path, prefix)
    try:
        p = prefix
        # an INP that names nothing: refused, the old one kept
        # (the put-callback reports the refusal: a `caput -c` sees it fail)
        assert put_status(p + "PCOMP1:INP", "ax9.enc.actpos") == ECA_PUTFAIL
        assert text(p + "PCOMP1:INP") == "ax3.enc.actpos"
        assert put_status(p + "PCOMP1:PRE_START", -1.0) == ECA_PUTFAIL
        assert get(p + "PCOMP1:PRE_START") == 0
        # an INP the block can compare (while it is disabled) is taken
        put(p + "PCOMP1:INP", "ax1.enc.actpos")
        assert text(p + "PCOMP1:INP") == "ax1.enc.actpos"
        # a file that cannot be created: the capture does not start and says why
        epics.caput(p + "PCAP:FILE_PATH", "/nonexistent/dir", wait=True)
        put(p + "PCAP:ARM", 1)
        assert wait_for(lambda: get(p + "PCAP:ERROR") == 1, 5)
        assert "/nonexistent/dir" in text(p + "PCAP:STATUS")
        assert get(p + "PCAP:ACTIVE") == 0
        assert srv.alive()
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


def test_timestamped_output_switches_between_frames(tmp_path, prefix):
    require_binary()
    data = tmp_path / "data"
    data.mkdir()
    # every cycle's 10 EL3702 samples (the EL4732 read back) and the EL4732's own, into the file
    capture = ("capture:\n  trigger: cycle\n  fields:\n"
               "    - {signal: ec0.s7.mm.analogInputArray01, name: ai}\n"
               "    - {signal: ec0.s6.mm.analogOutputArray01, name: ao}\n"
               "  storages: [2]\n"
               f"  last_rows: 50\n  file_path: {data}\n  file_name: samples_%03d.h5\n")
    # and a data storage a PLC appends the arc to at each EL4732 edge: those values into the file too
    (tmp_path / "edges.plc").write_text(
        "if (pcomp4.out <> static.was) { ds_append_data(2, ax3.traj.setpos); };\nstatic.was := pcomp4.out;\n")
    plc = f"storages:\n  - {{id: 2, size: 3, type: ring}}\nplcs:\n  - {{id: 1, file: {tmp_path / 'edges.plc'}}}\n"
    # and a record of a .db file on the block's pulse count (device support "@pcomp1.produced")
    (tmp_path / "made.db").write_text(
        'record(longin, "$(P)Made") { field(DTYP, "beamctl") field(INP, "@pcomp1.produced") field(SCAN, "I/O Intr") }\n')
    capture += f"db:\n  - {{file: {tmp_path / 'made.db'}, macros: {{P: '{prefix}'}}}}\n"
    srv, port = start(tmp_path, prefix, "timestamped.yaml", capture, plc)
    try:
        p = prefix
        assert text(p + "PCOMP3:INP") == "ax3.traj.setpos"
        put(p + "PCAP:ARM", 1)
        assert wait_for(lambda: get(p + "PCAP:ACTIVE") == 1, 5)
        put(p + "PCOMP1:ENABLE", 1)
        put(p + "PCOMP3:ENABLE", 1)
        put(p + "PCOMP4:ENABLE", 1)
        plain = p + "m0s005-timestampLatchPositive01"
        timed = p + "m0s005-timestampLatchPositive02"
        before = (get(plain), get(timed))
        missed_before = get(p + "m0-ThdMissedCycles")
        # 2.5 mm of arc: rises at 0.8, 1.6, 2.4 mm and falls at 1.2, 2.0 mm on both outputs
        motor = epics.Motor(p + "SpiralL")
        assert motor.move(2.5, wait=False) in (0, 1)  # 1: MOVN was already seen
        assert wait_for(lambda: get(p + "SpiralL.DMOV") == 1 and get(p + "SpiralL.MOVN") == 0, 30)
        assert wait_for(lambda: get(p + "PCOMP3:TIMED") == 5, 5)
        assert get(p + "PCOMP1:PRODUCED") == 3
        assert get(p + "PCOMP3:PRODUCED") == 3
        assert get(p + "PCOMP3:LATE") == 0
        assert get(p + "PCOMP1:TIMED") == 0  # the EL2808 block: plain
        assert wait_for(lambda: get(p + "Made") == 3, 5)
        # the EL4732 block placed the same 5 edges; the EL3702 reads its 10 samples per cycle back
        assert get(p + "PCOMP4:TIMED") == 5
        assert get(p + "PCOMP4:PRODUCED") == 3
        samples = epics.caget(p + "m0s007-AI01-Arr", timeout=5)
        assert len(samples) == 10 and set(samples) <= {0, 16384}, samples
        # the last rise (2.4 mm) latched on both: the timestamped edge came first, by less than
        # two cycles (1 kHz) and the slots the engine missed, and is not on the 1 ms frame grid the
        # plain one is on
        after = (get(plain), get(timed))
        assert after[0] != before[0] and after[1] != before[1]
        missed = get(p + "m0-ThdMissedCycles") - missed_before
        lead_ns = after[0] - after[1]
        assert 0 < lead_ns <= 2_000_000 + 1_000_000 * missed, (lead_ns, missed)
        # the capture: a [rows, 10] dataset of each channel; the input is the output two cycles
        # later, sample by sample, steps inside a cycle included
        live = epics.caget(p + "PCAP:LAST:ai", timeout=5)
        assert len(live) == 500 and set(live) <= {0, 16384}, live
        put(p + "PCAP:DISARM", 1)
        assert wait_for(lambda: get(p + "PCAP:ACTIVE") == 0 and get(p + "PCAP:FILES") == 1, 10)
        assert get(p + "PCAP:ROWS_DROPPED") == 0
        with h5py.File(data / "samples_001.h5", "r") as f:
            ai, ao = f["entry/data/ai"][()], f["entry/data/ao"][()]
            assert f["entry/data/ai"].attrs["samples_per_row"] == 10
            assert f["entry/data/ai"].attrs["source"] == "ec0.s7.mm.analogInputArray01"
        assert ai.shape[1] == 10 and ao.shape == ai.shape and ai.shape[0] > 1000, ai.shape
        assert (ai[2:] == ao[:-2]).all()
        # the 5 edges' arc positions (the storage itself keeps 3): 0.8, 1.2, ... 2.4 mm, just past
        with h5py.File(data / "samples_001.h5", "r") as f:
            assert f["entry/ds2"].attrs["NX_class"] == "NXlog"
            arc = f["entry/ds2/value"][()]
            assert f["entry/ds2/cycle"].shape == arc.shape
        assert len(arc) == 5, arc
        assert np.all(arc >= [0.8, 1.2, 1.6, 2.0, 2.4]) and np.all(arc < np.array([0.8, 1.2, 1.6, 2.0, 2.4]) + 0.01), arc
        steps_inside = [r for r in range(len(ao)) if 0 < np.count_nonzero(ao[r]) < 10]
        assert len(steps_inside) >= 2, steps_inside  # of the 5 edges
        assert srv.alive()
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)
