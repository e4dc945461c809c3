"""The RCP UDP bridge (specs/rcp-udp.md) seen by pyepics, against two kinds of RCP machine:
an independent packet writer written here from the spec (struct layouts, not beamctl's code),
and `beamctl rcp-sim examples/rcp/model.yaml`. PVs appear from beacons with the right types
and counts, values stream, writes reach the machine with the spec's byte layout, beacon changes
add and retire PVs, silence raises INVALID/COMM and data clears it, malformed packets change no
PV, and the MOTOR object is a motor record that pyepics moves, stops and keeps in its limits.
With rcp-sim stopped (offline) puts fail and change nothing, motor moves end in alarm and are
never replayed, and when it runs again the setpoints show the machine's values.

Nothing here is asserted against the wall clock: the tests wait for what they check (with
deadlines that only end a hung test), rates are measured on the IOC's own timestamps, and "nothing
happens for a while" is measured in the machine's own steps (its Counter), so a loaded machine
makes them slower, not red."""

import contextlib
import ctypes
import socket
import struct
import subprocess
import time

import epics
import pytest
from epics import ca

import ca_raw as raw
from conftest import BEAMCTL, REPO_ROOT, RunServer, acquire_port, connect, forget_pvs, release_port, wait_for

LOCAL = 0x7F000001  # 127.0.0.1 as the spec's u32
AI, AO, BI, BO, LI, LO, MOTOR = 1, 2, 3, 4, 5, 6, 7
BOOL, INT16, INT32, FLOAT32, FLOAT64 = 0, 3, 5, 7, 8
FMT = {BOOL: "B", INT16: "h", INT32: "i", FLOAT32: "f", FLOAT64: "d"}


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def name40(text):
    b = text.encode()
    assert len(b) <= 39
    return b + b"\0" * (40 - len(b))


def beacon(app, objects, version=1, ts=1.0):
    """objects: (id, type, data_type, port_rcp, port_ioc, name) on 127.0.0.1."""
    p = struct.pack("<dB", ts, version) + name40(app)
    for oid, otype, dtype, port_rcp, port_ioc, name in objects:
        p += struct.pack("<BBBIHIH", oid, otype, dtype, LOCAL, port_rcp, LOCAL, port_ioc) + name40(name)
    p += b"\0"
    assert len(p) <= 1000
    return p.ljust(1000, b"\0")


def data(entries, ts=2.0):
    """entries: (id, type, data_type, name, [values])."""
    p = struct.pack("<d", ts)
    for oid, otype, dtype, name, values in entries:
        p += struct.pack("<BBBH", oid, otype, dtype, len(values)) + name40(name)
        p += struct.pack("<%d%s" % (len(values), FMT[dtype]), *values)
    p += b"\0"
    assert len(p) <= 1000
    return p.ljust(1000, b"\0")


def parse_data(packet):
    """The spec's data packet, parsed independently: (timestamp, [(id, type, dtype, name, values)])."""
    assert len(packet) == 1000
    ts, = struct.unpack_from("<d", packet, 0)
    at, entries = 8, []
    while packet[at] != 0:
        oid, otype, dtype, count = struct.unpack_from("<BBBH", packet, at)
        raw = packet[at + 5:at + 45]
        assert b"\0" in raw
        name = raw.split(b"\0")[0].decode()
        fmt = "<%d%s" % (count, FMT[dtype])
        values = struct.unpack_from(fmt, packet, at + 45)
        entries.append((oid, otype, dtype, name, list(values)))
        at += 45 + struct.calcsize(fmt)
    assert not any(packet[at:])  # zero padding after the terminating id 0
    return ts, entries


@contextlib.contextmanager
def bridge_ioc(tmp_path, prefix, timeout_s=1.0):
    """A bus-less IOC: only ioc:, bridges: and ca: (valid per the issue)."""
    port = acquire_port()
    rcp_port = free_udp_port()
    cfg = tmp_path / "ioc.yaml"
    cfg.write_text(f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}\n'
                   f'bridges:\n  rcp: {{listen: 127.0.0.1, port: {rcp_port}, prefix: "{prefix}RCP:", '
                   f'timeout_s: {timeout_s}, db_out: rcp.db, motor_fields: {{DHLM: 45, DLLM: -45}}}}\n')
    srv = RunServer(tmp_path, cfg, port).start()
    try:
        yield srv, rcp_port
    finally:
        srv.stop()
        srv.kill()
        forget_pvs(prefix)
        release_port(port)


def exists(name, timeout=0.5):
    chid = ca.create_channel(name, connect=False, auto_cb=False)
    return ca.connect_channel(chid, timeout=timeout)


DEADLINE = 30  # [s] only ends a hung test: every wait below returns as soon as its condition holds


def served(srv, name):
    """The server's own answer to CREATE_CHAN on a fresh circuit: True (the channel), False
    (CREATE_CH_FAIL). Definite either way, unlike a libca search that did not connect in time."""
    with raw.Circuit("127.0.0.1", srv.port, timeout=DEADLINE) as c:
        return c.create(name, timeout=DEADLINE) is not None


def value_and_time(name):
    """(value, IOC timestamp [s]) of one fresh read."""
    chid = connect(name)
    md = ca.get_with_metadata(chid, ftype=ca.promote_type(chid, use_time=True), timeout=DEADLINE)
    return md["value"], md["timestamp"]


def machine_steps(p, n):
    """Waits until the machine (rcp-sim, prefix p) has run n more model steps, as its Counter
    (one a step) shows: "for a while" in the machine's time, not in this client's."""
    c0 = ca.get(connect(p + "Counter"))
    assert wait_for(lambda: ca.get(connect(p + "Counter")) >= c0 + n, timeout=60), \
        f"{p}Counter stays below {c0 + n}: the machine does not run"


OBJECTS = [
    (1, AI, FLOAT64, 0, 0, "Temp"),
    (2, AO, FLOAT64, 0, 0, "Set"),
    (3, BI, BOOL, 0, 0, "Ready"),
    (4, BO, BOOL, 0, 0, "Go"),
    (5, LI, INT32, 0, 0, "Count"),
    (6, LO, INT16, 0, 0, "Mode"),
    (7, AI, FLOAT64, 0, 0, "Wave"),
    (8, MOTOR, FLOAT64, 0, 0, "Axis"),
]


def test_packets_from_an_independent_writer(tmp_path, prefix):
    # timeout_s 3 (the default): the application stays online between this test's packets even
    # when a loaded machine runs the test slowly (the silence below is waited for, however long)
    with bridge_ioc(tmp_path, prefix, timeout_s=3.0) as (srv, rcp_port):
        rcp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        rcp.bind(("127.0.0.1", 0))
        rcp.settimeout(DEADLINE)
        my_port = rcp.getsockname()[1]
        objs = [(i, t, d, my_port, rcp_port, n) for i, t, d, _, _, n in OBJECTS]
        bridge = ("127.0.0.1", rcp_port)
        p = f"{prefix}RCP:pyRcp:"
        assert not served(srv, p + "Axis")  # nothing before the beacon
        rcp.sendto(beacon("pyRcp", objs), bridge)
        # the first beacon makes the PVs, with the types of the spec's table
        assert wait_for(lambda: served(srv, p + "Axis"), timeout=DEADLINE)
        assert wait_for(lambda: exists(p + "Axis"), timeout=DEADLINE)
        want = {"Temp": "ai", "Set": "ao", "Set_RBV": "ai", "Ready": "bi", "Go": "bo", "Go_RBV": "bi",
                "Count": "longin", "Mode": "longout", "Mode_RBV": "longin", "Wave": "ai", "Axis": "motor"}
        for n, rtype in want.items():
            assert ca.get(connect(p + n + ".RTYP")) == rtype, n

        # data: values (and a count of 8 turns Wave into a waveform)
        first_data = data([(1, AI, FLOAT64, "Temp", [21.5]), (3, BI, BOOL, "Ready", [1]),
                           (5, LI, INT32, "Count", [-7]), (7, AI, FLOAT64, "Wave", [float(i) for i in range(8)]),
                           (8, MOTOR, FLOAT64, "Axis", [1.25, 0, 1 | 16 | 64, 0, 0])])
        rcp.sendto(first_data, bridge)
        assert wait_for(lambda: ca.get(connect(p + "Temp")) == 21.5, timeout=DEADLINE)
        assert ca.get(connect(p + "Ready")) == 1
        assert ca.get(connect(p + "Count")) == -7
        forget_pvs(p + "Wave")
        assert wait_for(lambda: exists(p + "Wave") and ca.get(connect(p + "Wave.RTYP")) == "waveform",
                        timeout=DEADLINE)
        wave = epics.PV(p + "Wave")
        assert wait_for(lambda: wave.get() is not None and len(wave.get()) == 8, timeout=DEADLINE)
        assert list(wave.get()) == [float(i) for i in range(8)]
        assert wait_for(lambda: abs(ca.get(connect(p + "Axis.RBV")) - 1.25) < 1e-9, timeout=DEADLINE)

        # writes: one packet to ip_rcp:port_rcp per put, in the spec's layout. The same data once
        # more first (nothing changes): the application is online however long the above took.
        rcp.sendto(first_data, bridge)
        assert wait_for(lambda: alarm(p + "Temp")[0] == 0, timeout=DEADLINE)
        ca.put(connect(p + "Set"), 3.25, wait=True)
        pkt, _ = rcp.recvfrom(2000)
        ts, entries = parse_data(pkt)
        assert entries == [(2, AO, FLOAT64, "Set", [3.25])]
        ca.put(connect(p + "Mode"), 2, wait=True)
        pkt, _ = rcp.recvfrom(2000)
        assert parse_data(pkt)[1] == [(6, LO, INT16, "Mode", [2])]
        ca.put(connect(p + "Go"), 1, wait=True)
        pkt, _ = rcp.recvfrom(2000)
        assert parse_data(pkt)[1] == [(4, BO, BOOL, "Go", [1])]
        # a motor move is a MOTOR command entry: [command 1 = move absolute, target, velocity,
        # acceleration, sequence number]
        ca.put(connect(p + "Axis"), 4.0)
        pkt, _ = rcp.recvfrom(2000)
        (oid, otype, dtype, name, v), = parse_data(pkt)[1]
        assert (oid, otype, dtype, name) == (8, MOTOR, FLOAT64, "Axis")
        assert v[0] == 1 and abs(v[1] - 4.0) < 1e-9 and v[2] > 0 and v[4] >= 1

        # malformed packets are counted and change no PV
        bad = {
            "Short": data([(1, AI, FLOAT64, "Temp", [99.0])])[:100],
            "WrongVersion": beacon("pyRcp", objs, version=2),
            "UnknownType": data([(1, 9, FLOAT64, "Temp", [99.0])]),
            "UnterminatedName": data([(1, AI, FLOAT64, "Temp", [99.0])])[:13] + b"T" * 40 + data([(1, AI, FLOAT64, "Temp", [99.0])])[53:],
            "CountOverflow": struct.pack("<dBBBH", 2.0, 1, AI, FLOAT64, 500) + name40("Temp") + b"\0" * 947,
            "TypeMismatch": data([(1, AI, INT32, "Temp", [99])]),
        }
        for reason, pkt in bad.items():
            assert len(pkt) == (100 if reason == "Short" else 1000), reason
            rcp.sendto(pkt, bridge)
        for reason in bad:
            assert wait_for(lambda: (ca.get(connect(f"{prefix}RCP:Malformed-{reason}")) or 0) >= 1,
                            timeout=DEADLINE), reason
        assert ca.get(connect(p + "Temp")) == 21.5
        assert ca.get(connect(p + "Count")) == -7

        # a changed beacon: Go is retired, New appears, the .db is rewritten
        objs2 = [o for o in objs if o[5] != "Go"] + [(9, AI, FLOAT64, my_port, rcp_port, "New")]
        rcp.sendto(beacon("pyRcp", objs2), bridge)
        assert wait_for(lambda: served(srv, p + "New"), timeout=DEADLINE)
        assert wait_for(lambda: exists(p + "New"), timeout=DEADLINE)
        # retired: the server answers CREATE_CHAN for Go with CREATE_CH_FAIL (not merely slowly)
        assert wait_for(lambda: not served(srv, p + "Go"), timeout=DEADLINE)
        assert served(srv, p + "Go_RBV") is False and served(srv, p + "Temp")
        forget_pvs(p + "Go")
        db = (tmp_path / "rcp.db").read_text()
        assert f'"{p}New"' in db and f'"{p}Go"' not in db

        # silence (timeout_s): INVALID/COMM; the next packet clears it
        temp = epics.PV(p + "Temp", form="ctrl")
        assert wait_for(lambda: temp.get_ctrlvars() and temp.severity == 3 and temp.status == 9, timeout=DEADLINE)
        rcp.sendto(data([(1, AI, FLOAT64, "Temp", [22.0])]), bridge)
        assert wait_for(lambda: temp.get(use_monitor=False) == 22.0 and temp.severity == 0, timeout=DEADLINE)
        rcp.close()


MODEL = REPO_ROOT / "examples" / "rcp" / "model.yaml"


@contextlib.contextmanager
def rcp_sim(rcp_port, extra=(), sim_port=None, model=MODEL):
    sim_port = sim_port or free_udp_port()
    proc = subprocess.Popen([str(BEAMCTL), "rcp-sim", str(model),
                             "--ioc-port", str(rcp_port), "--port", str(sim_port), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL)
    try:
        line = proc.stdout.readline().decode()
        assert line.startswith("ready:"), line + proc.stderr.read().decode()
        yield proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_rcp_sim_values_writes_and_motor(tmp_path, prefix):
    with bridge_ioc(tmp_path, prefix, timeout_s=3) as (srv, rcp_port), rcp_sim(rcp_port):
        p = f"{prefix}RCP:sgDemo:"
        assert wait_for(lambda: exists(p + "Stage"), timeout=DEADLINE)
        # values stream at the model's rate (100 Hz): the int32 counter advances by one a step, and
        # every Sine value comes as a monitor update. Both rates are measured on the IOC's clock
        # (the timestamps of the values it received), over at least 2 s of it.
        updates = []
        sine = epics.PV(p + "Sine", callback=lambda value=None, timestamp=None, **kw: updates.append((value, timestamp)))
        c0, t0 = value_and_time(p + "Counter")
        assert wait_for(lambda: value_and_time(p + "Counter")[1] - t0 >= 2.0, timeout=DEADLINE), \
            f"{p}Counter is not updated: {value_and_time(p + 'Counter')} after {(c0, t0)}"
        c1, t1 = value_and_time(p + "Counter")
        rate = (c1 - c0) / (t1 - t0)
        assert 50 <= rate <= 150, f"Counter {c0} -> {c1} in {t1 - t0:.3f} s of IOC time: {rate:.1f} Hz"
        assert wait_for(lambda: len(updates) >= 2 and updates[-1][1] - updates[0][1] >= 2.0, timeout=DEADLINE)
        sine.clear_callbacks()
        got = list(updates)
        stamps = [t for _, t in got]
        assert stamps == sorted(stamps), "monitor updates in the order the IOC stamped them"
        sine_rate = (len(got) - 1) / (stamps[-1] - stamps[0])
        assert sine_rate >= 50, f"{len(got)} Sine updates in {stamps[-1] - stamps[0]:.3f} s of IOC time"
        assert all(abs(v) <= 1.0 for v, _ in got) and len({v for v, _ in got}) > len(got) // 2, got[:20]
        assert ca.get(connect(p + "Spectrum.NELM")) == 16
        # a write reaches the model: its readback comes back in the model's data
        ca.put(connect(p + "Setpoint"), 2.0, wait=True)
        assert wait_for(lambda: ca.get(connect(p + "Setpoint_RBV")) == 2.0, timeout=DEADLINE)
        assert wait_for(lambda: abs(ca.get(connect(p + "PlantOut")) - 2.0) < 0.05, timeout=DEADLINE)
        assert wait_for(lambda: ca.get(connect(p + "InTolerance")) == 1, timeout=DEADLINE)
        # the motor record on the MOTOR object
        m = epics.Motor(p + "Stage", timeout=DEADLINE)
        assert m.move(5.0, wait=True, timeout=60) == 0
        assert abs(m.get("RBV") - 5.0) < 0.01
        assert m.get("DMOV") == 1
        m.move(40.0)
        assert wait_for(lambda: m.get("MOVN") == 1, timeout=DEADLINE)
        m.stop()
        assert wait_for(lambda: ca.get(connect(p + "Stage.DMOV")) == 1, timeout=DEADLINE)
        stopped = ca.get(connect(p + "Stage.RBV"))
        assert 5.0 < stopped < 40.0
        machine_steps(p, 30)  # the machine runs on: the stage stays where it stopped
        assert ca.get(connect(p + "Stage.RBV")) == stopped
        assert m.move(100.0, wait=True) == -12  # beyond the record's high limit (45)
        assert ca.get(connect(p + "Stage.HLM")) == 45
        # diagnostics
        assert ca.get(connect(p + "RxCount")) > 100
        assert ca.get(connect(p + "Online")) == 1


ECA_NORMAL = 1
INVALID, COMM = 3, 9  # severity, status


def put_callback_status(name, value, timeout=5.0):
    """A CA put-callback of one double through pyepics' libca; returns the ECA status the server
    completed it with (pyepics' own put(wait=True) does not report it)."""
    chid = connect(name)
    done = {}

    def on_done(args):
        done["status"] = args.status

    cb = epics.dbr.make_callback(on_done, epics.dbr.event_handler_args)
    value_buf = (ctypes.c_double * 1)(value)
    usr = ctypes.py_object(done)
    ret = ca.libca.ca_array_put_callback(epics.dbr.DOUBLE, 1, chid, value_buf, cb, usr)
    assert ret == ECA_NORMAL, ret
    ca.flush_io()
    assert wait_for(lambda: "status" in done, timeout=timeout), f"no put-callback from {name}"
    return done["status"]


def alarm(name):
    """(severity, status) read now."""
    chid = connect(name)
    md = ca.get_with_metadata(chid, ftype=ca.promote_type(chid, use_time=True))
    return md["severity"], md["status"]


def test_rcp_sim_offline_refuses_writes_and_setpoints_follow_it_back(tmp_path, prefix):
    with bridge_ioc(tmp_path, prefix, timeout_s=1.0) as (srv, rcp_port):
        p = f"{prefix}RCP:sgDemo:"
        sim_port = free_udp_port()  # the restarted machine listens where it did
        with rcp_sim(rcp_port, sim_port=sim_port):
            assert wait_for(lambda: exists(p + "Stage"), timeout=DEADLINE)
            assert epics.caput(p + "Setpoint", 2.0, wait=True) == 1
            assert wait_for(lambda: ca.get(connect(p + "Setpoint_RBV")) == 2.0, timeout=DEADLINE)
            m = epics.Motor(p + "Stage", timeout=DEADLINE)
            m.put("VELO", 10.0, wait=True)
            assert m.move(5.0, wait=True, timeout=60) == 0
            assert abs(m.get("RBV") - 5.0) < 0.01
            # a long move (VELO 1: 35 s) in progress when the machine stops: the machine has
            # reported the stage moving on from 5
            m.put("VELO", 1.0, wait=True)
            m.move(40.0)
            assert wait_for(lambda: m.get("MOVN") == 1 and ca.get(connect(p + "Stage.RBV")) > 5.05, timeout=DEADLINE)
        # rcp-sim stopped: after timeout_s of silence every PV is INVALID/COMM; the move in
        # progress ended (DMOV 1) in alarm, its target dropped (VAL = RBV), the MSTA problem bit set
        assert wait_for(lambda: alarm(p + "Setpoint") == (INVALID, COMM), timeout=DEADLINE)
        def field(name):  # a fresh read, not pyepics' latest monitor update
            return ca.get(connect(p + "Stage." + name))

        assert wait_for(lambda: field("DMOV") == 1, timeout=DEADLINE)
        assert alarm(p + "Stage") == (INVALID, COMM)
        stopped = field("RBV")
        assert 5.0 < stopped < 40.0
        assert abs(field("VAL") - stopped) < 1e-3
        assert int(field("MSTA")) & (1 << 9), "MSTA problem: the move failed"

        # puts fail: the put-callback reports an error, the value does not change
        assert put_callback_status(p + "Setpoint", 7.0) != ECA_NORMAL
        epics.caput(p + "Setpoint", 7.0, wait=True)
        epics.caput(p + "Setpoint", 8.0)
        time.sleep(0.2)
        assert ca.get(connect(p + "Setpoint")) == 2.0
        assert alarm(p + "Setpoint") == (INVALID, COMM)
        assert put_callback_status(p + "Mode", 2) != ECA_NORMAL
        assert ca.get(connect(p + "Mode")) == 0

        # a motor move while offline fails: it ends at once in alarm and keeps no target
        m.move(-20.0, wait=True, timeout=DEADLINE)
        assert field("DMOV") == 1
        assert abs(field("VAL") - stopped) < 1e-3
        assert alarm(p + "Stage") == (INVALID, COMM)

        # the machine restarts (its initial values: Setpoint 0, Stage at 0)
        with rcp_sim(rcp_port, sim_port=sim_port):
            assert wait_for(lambda: alarm(p + "Setpoint") == (0, 0), timeout=DEADLINE)
            assert wait_for(lambda: alarm(p + "Stage")[0] == 0, timeout=DEADLINE)
            # the alarms clear with the machine's beacon, the values come with its data: wait for
            # the values (readbacks at the restarted machine's 0, and the setpoint and the motor's
            # target taking them), not for the alarms alone, which can precede them
            sp, rbv = connect(p + "Setpoint"), connect(p + "Setpoint_RBV")
            assert wait_for(lambda: ca.get(rbv) == 0.0 and ca.get(sp) == ca.get(rbv), timeout=DEADLINE), \
                (ca.get(sp), ca.get(rbv))
            assert ca.get(sp) == 0.0
            stage_val, stage_rbv = connect(p + "Stage.VAL"), connect(p + "Stage.RBV")
            assert wait_for(lambda: abs(ca.get(stage_rbv)) < 1e-3 and abs(ca.get(stage_val) - ca.get(stage_rbv)) < 1e-3,
                            timeout=DEADLINE), (ca.get(stage_val), ca.get(stage_rbv))
            # nothing refused or interrupted is sent now: the machine stays where it started for
            # 150 of its steps (1.5 s of its time), by when a replayed write would show
            machine_steps(p, 150)
            assert ca.get(rbv) == 0.0
            assert abs(ca.get(stage_rbv)) < 1e-3 and abs(ca.get(stage_val)) < 1e-3
            assert ca.get(connect(p + "Stage.DMOV")) == 1
            assert ca.get(connect(p + "Mode_RBV")) == 0
            # and writes work again
            assert put_callback_status(p + "Setpoint", 1.5) == ECA_NORMAL
            assert wait_for(lambda: ca.get(rbv) == 1.5, timeout=DEADLINE)
            assert m.move(1.0, wait=True, timeout=60) == 0
            assert abs(m.get("RBV") - 1.0) < 0.01


def test_rcp_sim_data_before_its_beacon_is_not_malformed(tmp_path, prefix):
    """rcp-sim runs before the IOC (as in the demo): the IOC gets its data before a beacon. That
    is counted in DataBeforeBeacon, not as malformed, and not logged at warn."""
    model = tmp_path / "model.yaml"
    text = MODEL.read_text()
    assert "beacon_period_s: 1\n" in text
    # 5 s between beacons, so the IOC (however slowly it starts) is up before the second one,
    # and a bridge timeout_s of 10: a few seconds of data before a beacon is the usual start, not
    # a misconfiguration worth a warning
    model.write_text(text.replace("beacon_period_s: 1\n", "beacon_period_s: 5\n"))
    port = acquire_port()
    rcp_port = free_udp_port()
    with rcp_sim(rcp_port, model=model):  # its first beacon goes unheard; the next is 5 s later
        cfg = tmp_path / "ioc.yaml"
        cfg.write_text(f'ioc: {{name: {prefix.rstrip(":")}, prefix: "{prefix}"}}\n'
                       f'bridges:\n  rcp: {{listen: 127.0.0.1, port: {rcp_port}, prefix: "{prefix}RCP:", '
                       f'timeout_s: 10}}\n')
        srv = RunServer(tmp_path, cfg, port).start()
        try:
            p = f"{prefix}RCP:"
            assert ca.get(connect(p + "Applications")) == 0
            # the next beacon makes the application's PVs
            assert wait_for(lambda: served(srv, p + "sgDemo:Stage"), timeout=60)
            assert wait_for(lambda: exists(p + "sgDemo:Stage"), timeout=DEADLINE)

            # every packet the IOC received is counted once: the data before the beacon in
            # DataBeforeBeacon, the rest (beacon and data) as the application's. The counters are
            # published together once a second; a snapshot is one publication if the global
            # RxCount read before and after it is the same (data keeps coming at 100 Hz).
            def get(n):
                return ca.get(connect(p + n))

            def snapshot():
                rx0, early, app_rx, rx1 = get("RxCount"), get("DataBeforeBeacon"), get("sgDemo:RxCount"), get("RxCount")
                return (rx0, early, app_rx) if rx0 == rx1 and app_rx > 0 else None

            snap = wait_for(snapshot, timeout=DEADLINE)
            assert snap, "no consistent publication of the counters"
            rx, early, app_rx = snap
            assert early >= 1, "the data before the beacon was counted in DataBeforeBeacon"
            assert rx == early + app_rx, f"RxCount {rx} = DataBeforeBeacon {early} + sgDemo:RxCount {app_rx}"
            # once the beacon came, data is the application's: DataBeforeBeacon stays
            machine_steps(p + "sgDemo:", 150)
            assert get("DataBeforeBeacon") == early
            assert get("sgDemo:RxCount") > app_rx
            for reason in ("UnknownApplication", "UnknownObject", "TypeMismatch"):
                assert ca.get(connect(p + "Malformed-" + reason)) == 0, reason
            assert ca.get(connect(p + "sgDemo:Online")) == 1
            assert "malformed" not in srv.stderr()
            assert "before any beacon" not in srv.stderr()  # debug only
        finally:
            srv.stop()
            srv.kill()
            forget_pvs(prefix)
            release_port(port)


def test_rcp_objects_are_in_the_running_iocs_signal_registry(tmp_path, prefix):
    """`beamctl shell` -> `signals rcp.*`: the objects the beacon announced, with their PVs."""
    from test_shell import shell, socket_of
    with bridge_ioc(tmp_path, prefix, timeout_s=3) as (srv, rcp_port), rcp_sim(rcp_port):
        p = f"{prefix}RCP:sgDemo:"
        assert wait_for(lambda: exists(p + "Stage"), timeout=DEADLINE)
        rc, out, err = shell(socket_of(srv), "signals rcp.*")
        assert rc == 0, out + err
        stage = [l for l in out.splitlines() if l.startswith("rcp.sgDemo.Stage ")]
        assert len(stage) == 1, out
        assert p + "Stage" in stage[0] and "rcp sgDemo (MOTOR)" in stage[0], stage
        assert stage[0].split()[1:3] == ["LREAL", "variable"], stage
        assert "rcp.sgDemo.Setpoint" in out and "rcp.sgDemo.Counter" in out, out
        rc, out, err = shell(socket_of(srv), "signals nothing.like.this*")
        assert rc != 0 and "no signal matches" in out, out + err
