#!/usr/bin/python3
"""Conformance of `beamctl softioc` against EPICS softIoc, seen from a Channel Access client.

Both servers load the same databases (bench/db/conformance.db, conformance_arrays.db,
conformance_issue41.db, conformance_monitors.db, and one record of every type of softIoc.dbd
with its defaults and one for puts), one after the other, each on its own
free port; a separate client process (pyepics on its own libca) applies the same sequence of puts
and records what it sees: value, alarm status/severity and the DBR_CTRL metadata (units,
precision, display/alarm/control limits, enum strings), the record's STAT/SEVR/UDF fields, and the
completion status of numeric gets of string records; the events of DBE_VALUE/LOG/ALARM
subscriptions (MDEL, ADEL, HYST), IVOA, SDLY; every field of every record type as DBR_STRING with
its native type and count, and the completion status of a put to every settable field. The two
observation sets are then compared item by item.

  /usr/bin/python3 bench/conformance_db.py [--softioc PATH] [--beamctl PATH] [--md OUT.md] [--dbd PATH]

Without --softioc (or $SOFTIOC) only beamctl is observed and the observations are printed. Nothing
here is needed by the build or the tests.
"""
import argparse, ctypes, json, math, os, socket, subprocess, sys, tempfile, time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DB = os.path.join(HERE, "db", "conformance.db")
DB_ARRAYS = os.path.join(HERE, "db", "conformance_arrays.db")
DB_41 = os.path.join(HERE, "db", "conformance_issue41.db")
DB_MON = os.path.join(HERE, "db", "conformance_monitors.db")


def dbd_sweep(dbd_path):
    """[(record type, [(field, DBF type, settable)])] from an expanded .dbd (softIoc.dbd):
    every field of every record type; settable = neither DBF_NOACCESS nor SPC_NOMOD."""
    import re
    out, cur, fld = [], None, None
    for line in open(dbd_path):
        m = re.match(r'\s*recordtype\((\w+)\)', line)
        if m:
            cur = (m.group(1), [])
            out.append(cur)
            continue
        m = re.match(r'\s*field\((\w+),\s*(DBF_\w+)\)', line)
        if m and cur:
            fld = [m.group(1), m.group(2), m.group(2) != "DBF_NOACCESS"]
            cur[1].append(fld)
            continue
        if fld and "special(SPC_NOMOD)" in line:
            fld[2] = False
    return out


def sweep_db(sweep, path):
    """One record of each type with its defaults (cf:t:TYPE) and one for the puts (cf:p:TYPE)."""
    with open(path, "w") as f:
        for rtype, _ in sweep:
            for p in ("t", "p"):
                f.write(f'record({rtype}, "cf:{p}:{rtype}") {{}}\n')

PVS = """cf:in cf:c1 cf:c2 cf:c3 cf:co cf:coout cf:co2 cf:co2out cf:co3 cf:co3cnt cf:seq cf:seq1
cf:seq2 cf:seq3 cf:cp cf:cp2 cf:src cf:ms cf:nms cf:mss cf:msout cf:ao_init cf:ai_init cf:li_init
cf:lo_init cf:calc_init cf:ao_noval cf:so_init cf:bi cf:bo cf:bofollow cf:mbbi cf:mbbo
cf:mbbi_nostates cf:si cf:si_num""".split()
ENUMS = ["cf:bi", "cf:bo", "cf:mbbi", "cf:mbbo", "cf:mbbi_nostates"]

# ---------------------------------------------------------------------------------------------
# client side (runs in its own process: pyepics reads EPICS_CA_* once, at context creation)


def client(out_path):
    import epics
    from epics import ca, dbr

    chids = {}

    def chan(name):
        if name not in chids:
            c = ca.create_channel(name, connect=False, auto_cb=False)
            if not ca.connect_channel(c, timeout=3.0):
                chids[name] = None
            else:
                chids[name] = c
        return chids[name]

    obs = {}

    def put(name, value, wait=True):
        if isinstance(value, str):  # by name (pyepics maps enum names through the PV's ctrl data)
            st = epics.caput(name, value, wait=wait, timeout=3.0)
        else:
            st = ca.put(chan(name), value, wait=wait, timeout=3.0)
        ca.poll(0.3)  # let CP links (scanOnce) and delayed work settle
        time.sleep(0.3)
        return st

    meta_keys = ["value", "status", "severity", "units", "precision", "upper_disp_limit",
                 "lower_disp_limit", "upper_alarm_limit", "upper_warning_limit",
                 "lower_warning_limit", "lower_alarm_limit", "upper_ctrl_limit",
                 "lower_ctrl_limit", "enum_strs"]

    def norm(v):
        if isinstance(v, bytes):
            return v.decode(errors="replace")
        if isinstance(v, (list, tuple, ctypes.Array)):
            return [norm(x) for x in v]
        if hasattr(v, "tolist"):
            return norm(v.tolist())
        if isinstance(v, float) and (math.isnan(v) or math.isinf(v)):
            return repr(v)
        return v

    def md(c, ftype):
        try:
            d = ca.get_with_metadata(c, ftype=ftype, as_numpy=False, timeout=3.0)
        except Exception as e:  # noqa
            return {"error": repr(e)}
        if d is None:
            return {"error": "no answer"}
        return {k: norm(d[k]) for k in meta_keys if k in d}

    t_start = time.time()
    last_step = [None]

    def progress(step):
        if step != last_step[0]:
            last_step[0] = step
            print(f"[{time.time() - t_start:7.1f} s] {step}", file=sys.stderr, flush=True)

    def snap(step, names):
        progress(step)
        for n in names:
            c = chan(n)
            if c is None:
                obs[f"{step}|{n}|connect"] = "NOT CONNECTED"
                continue
            ft = ca.field_type(c)
            native = dbr.Name(ft) if hasattr(dbr, "Name") else str(ft)
            obs[f"{step}|{n}|native type"] = native
            ctrl = ca.promote_type(c, use_ctrl=True)
            for k, v in md(c, ctrl).items():
                obs[f"{step}|{n}|CTRL.{k}"] = v
            t = ca.get_with_metadata(c, ftype=ca.promote_type(c, use_time=True), as_numpy=False,
                                     timeout=3.0) or {}
            ts = t.get("timestamp")
            obs[f"{step}|{n}|TIME.timestamp is EPICS epoch 0"] = (ts is not None and ts <= 631152000.0 + 1e-6)
            for f in ("STAT", "SEVR", "UDF"):
                fc = chan(f"{n}.{f}")
                obs[f"{step}|{n}|.{f}"] = None if fc is None else norm(ca.get(fc, ftype=dbr.STRING, timeout=3.0))
            if n in ENUMS:
                for ftn, ftc in (("CTRL_LONG", dbr.CTRL_LONG), ("CTRL_DOUBLE", dbr.CTRL_DOUBLE)):
                    for k, v in md(c, ftc).items():
                        if k in ("value", "units", "precision", "upper_disp_limit", "lower_disp_limit",
                                 "upper_ctrl_limit", "lower_ctrl_limit", "upper_alarm_limit",
                                 "lower_alarm_limit", "upper_warning_limit", "lower_warning_limit"):
                            obs[f"{step}|{n}|{ftn}.{k}"] = v

    # raw get-with-callback with our own callback, to see the completion status the server sends
    class Args(ctypes.Structure):
        _fields_ = [("usr", ctypes.c_void_p), ("chid", ctypes.c_void_p), ("type", ctypes.c_long),
                    ("count", ctypes.c_long), ("dbr", ctypes.c_void_p), ("status", ctypes.c_int)]

    CB = ctypes.CFUNCTYPE(None, Args)
    got = {}

    def on_get(a):
        val = None
        if a.status == 1 and a.dbr:
            ct = {dbr.SHORT: ctypes.c_short, dbr.LONG: ctypes.c_int, dbr.FLOAT: ctypes.c_float,
                  dbr.DOUBLE: ctypes.c_double, dbr.ENUM: ctypes.c_ushort, dbr.CHAR: ctypes.c_ubyte}[a.type]
            val = ctypes.cast(a.dbr, ctypes.POINTER(ct))[0]
        got["r"] = (a.status, val)

    cb = CB(on_get)
    chan("cf:in")
    libca = ca.libca
    get_cb = libca["ca_array_get_callback"]  # a private function object: pyepics keeps its own argtypes
    get_cb.argtypes = [ctypes.c_long, ctypes.c_ulong, ctypes.c_void_p, CB, ctypes.c_void_p]
    ca_message = libca["ca_message"]
    ca_message.restype = ctypes.c_char_p

    def raw_get(name, ftype, tname):
        c = chan(name)
        got.clear()
        st = get_cb(ftype, 1, c.value if hasattr(c, "value") else c, cb, None)
        libca.ca_flush_io()
        t0 = time.time()
        while "r" not in got and time.time() - t0 < 3:
            ca.poll(0.01)
        if "r" not in got:
            return f"request status {st}, no callback"
        s, v = got["r"]
        return f"status {s} ({ca_message(s).decode()}), value {v!r}"

    def numeric_gets(step, name):
        for tname, ft in (("DBR_SHORT", dbr.SHORT), ("DBR_LONG", dbr.LONG), ("DBR_FLOAT", dbr.FLOAT),
                          ("DBR_DOUBLE", dbr.DOUBLE), ("DBR_ENUM", dbr.ENUM), ("DBR_CHAR", dbr.CHAR)):
            obs[f"{step}|{name}|get {tname} (callback status, value)"] = raw_get(name, ft, tname)
        # what pyepics' own ca.get returns (it drops non-normal callbacks and times out)
        c = chan(name)
        try:
            v = ca.get(c, ftype=dbr.SHORT, as_numpy=False, timeout=1.0)
        except Exception as e:  # noqa
            v = repr(e)
        obs[f"{step}|{name}|pyepics ca.get(ftype=DBR_SHORT)"] = norm(v)

    def field(step, name):
        c = chan(name)
        obs[f"{step}|{name}|value"] = None if c is None else norm(ca.get(c, ftype=dbr.STRING, timeout=3.0))

    # ---- the sequence
    snap("0 init", PVS)
    numeric_gets("0 init", "cf:si")
    numeric_gets("0 init", "cf:si_num")

    chain = ["cf:in", "cf:c1", "cf:c2", "cf:c3", "cf:cp", "cf:cp2"]
    put("cf:in", 3.0)
    snap("1 put cf:in=3", chain)
    put("cf:in", 60.0)
    snap("2 put cf:in=60 (DRVH 50)", chain)
    put("cf:in", 4.0)
    snap("3 put cf:in=4", chain)

    put("cf:seq.PROC", 1)
    snap("4 put cf:seq.PROC=1", ["cf:seq", "cf:seq1", "cf:seq2", "cf:seq3"])

    put("cf:co.A", 0)
    snap("5 put cf:co.A=0", ["cf:co", "cf:coout"])
    field("5 put cf:co.A=0", "cf:co.OVAL")
    put("cf:co.A", 2)
    snap("6 put cf:co.A=2", ["cf:co", "cf:coout"])
    field("6 put cf:co.A=2", "cf:co.OVAL")
    put("cf:co2.A", 0)
    snap("7 put cf:co2.A=0", ["cf:co2", "cf:co2out"])
    put("cf:co2.A", -1)
    snap("8 put cf:co2.A=-1", ["cf:co2", "cf:co2out"])
    put("cf:co3.A", 1)
    put("cf:co3.A", 1)
    put("cf:co3.A", 2)
    snap("9 put cf:co3.A=1,1,2", ["cf:co3", "cf:co3cnt"])

    ms = ["cf:src", "cf:ms", "cf:nms", "cf:mss", "cf:msout"]
    put("cf:src", 20.0)
    snap("10 put cf:src=20 (HIHI)", ms)
    put("cf:src", 6.0)
    snap("11 put cf:src=6 (HIGH)", ms)
    put("cf:src", 1.0)
    snap("12 put cf:src=1", ms)

    put("cf:bo", 1)
    snap("13 put cf:bo=1", ["cf:bo", "cf:bofollow"])
    put("cf:mbbo", "Fast")
    snap("14 put cf:mbbo=Fast", ["cf:mbbo"])
    put("cf:mbbo", 1)
    snap("15 put cf:mbbo=1", ["cf:mbbo"])
    put("cf:mbbo", 7)
    snap("16 put cf:mbbo=7 (no such state)", ["cf:mbbo"])
    put("cf:bi.PROC", 1)
    snap("17 put cf:bi.PROC=1", ["cf:bi"])

    put("cf:si.PROC", 1)
    snap("18 put cf:si.PROC=1", ["cf:si"])
    numeric_gets("18 put cf:si.PROC=1", "cf:si")

    # ---- the array and small record types (bench/db/conformance_arrays.db)
    arr = ["cf:aao", "cf:wf", "cf:aai", "cf:aai_c", "cf:sa"]
    snap("19 arrays init", arr + ["cf:cmp", "cf:hist", "cf:perm", "cf:state", "cf:pf"])
    put("cf:aao", [1.5, 2, 3, 4, 5])
    snap("20 put cf:aao=[1.5,2,3,4,5]", arr)
    put("cf:sa.PROC", 1)
    snap("21 put cf:sa.PROC=1", ["cf:sa"])
    for f_ in ("cf:aao.NORD", "cf:wf.NORD", "cf:aai.NORD", "cf:aai_c.NORD", "cf:sa.NORD"):
        field("21 put cf:sa.PROC=1", f_)
    put("cf:sa.INDX", 3)
    snap("22 put cf:sa.INDX=3", ["cf:sa"])
    field("22 put cf:sa.INDX=3", "cf:sa.NORD")
    # without put-callback: softIoc never completes one whose processing reaches a compress that
    # keeps its value (N to 1 waiting for N: no recGblFwdLink, so no dbNotifyCompletion)
    for v in (1.0, 3.0, 5.0, 7.0, 9.0):
        put("cf:x", v, wait=False)
    cmp_ = ["cf:cmp", "cf:cmplifo", "cf:cmpavg", "cf:hist"]
    snap("23 put cf:x=1,3,5,7,9", cmp_)
    for f_ in ("cf:cmp.NUSE", "cf:cmp.OFF", "cf:cmplifo.NUSE", "cf:cmplifo.OFF", "cf:cmpavg.NUSE",
               "cf:cmpavg.INX", "cf:hist.WDTH", "cf:hist.MCNT", "cf:hist.CSTA"):
        field("23 put cf:x=1,3,5,7,9", f_)
    put("cf:cmpwf.PROC", 1)
    snap("24 put cf:cmpwf.PROC=1", ["cf:cmpwf"])
    put("cf:hist.CMD", "Clear")
    put("cf:hist.PROC", 1)
    snap("25 put cf:hist.CMD=Clear, PROC", ["cf:hist"])
    put("cf:cmp.RES", 1)
    snap("26 put cf:cmp.RES=1", ["cf:cmp"])
    put("cf:perm", 1)
    put("cf:perm.WFLG", 1)
    put("cf:state", "moving")
    put("cf:pf.PROC", 1)
    snap("27 permissive, state, printf", ["cf:perm", "cf:state", "cf:pf"])
    for f_ in ("cf:perm.OVAL", "cf:perm.OFLG", "cf:state.OVAL", "cf:pf.LEN"):
        field("27 permissive, state, printf", f_)

    # ---- issue 41 (bench/db/conformance_issue41.db): conversion, OROC, simulation mode, HIGH,
    # OOPT, NLST, values out of range of the DBR type asked for
    conv = ["cf:ai_slope", "cf:ai_linear", "cf:ao_slope", "cf:ao_raw"]
    snap("28 issue41 init", conv + ["cf:ai_sim", "cf:ai_siml", "cf:bo_sim", "cf:bo_high", "cf:sel"])
    put("cf:ai_slope.PROC", 1)
    put("cf:ai_linear.PROC", 1)
    snap("29 put PROC of the Raw Soft Channel ai's", ["cf:ai_slope", "cf:ai_linear"])
    for f_ in ("cf:ai_slope.RVAL", "cf:ai_linear.RVAL", "cf:ai_linear.ESLO", "cf:ai_linear.EOFF"):
        field("29 put PROC of the Raw Soft Channel ai's", f_)
    put("cf:ao_slope", 10.0)
    snap("30 put cf:ao_slope=10", ["cf:ao_slope", "cf:ao_raw"])
    for f_ in ("cf:ao_slope.RVAL", "cf:ao_slope.OVAL", "cf:ao_slope.ORAW"):
        field("30 put cf:ao_slope=10", f_)
    put("cf:ao_oroc", 5.0)
    field("31 put cf:ao_oroc=5 (OROC 1)", "cf:ao_oroc.OVAL")
    field("31 put cf:ao_oroc=5 (OROC 1)", "cf:ao_orocout")
    put("cf:ao_oroc.PROC", 1)
    field("32 then PROC", "cf:ao_oroc.OVAL")
    field("32 then PROC", "cf:ao_orocout")
    put("cf:ai_sim.SIMM", 1)
    put("cf:ai_sim.PROC", 1)
    snap("33 cf:ai_sim SIMM=1, PROC", ["cf:ai_sim"])
    put("cf:simmode", 1)
    put("cf:ai_siml.PROC", 1)
    snap("34 cf:simmode=1, cf:ai_siml PROC", ["cf:ai_siml"])
    field("34 cf:simmode=1, cf:ai_siml PROC", "cf:ai_siml.SIMM")
    put("cf:simmode", 0)
    put("cf:ai_siml.PROC", 1)
    snap("35 cf:simmode=0, cf:ai_siml PROC", ["cf:ai_siml"])
    put("cf:bo_sim", 1)
    snap("36 put cf:bo_sim=1 (SIMM YES)", ["cf:bo_sim", "cf:bo_real", "cf:bo_simout"])
    put("cf:bo_high", 1)  # the put's 0.6 s settle outlasts HIGH 0.2 s
    snap("37 put cf:bo_high=1, 0.6 s later", ["cf:bo_high"])
    for v in (5, 5, 6):
        put("cf:lo_oopt", v)
    snap("38 put cf:lo_oopt=5,5,6 (OOPT On Change)", ["cf:lo_oopt", "cf:lo_cnt"])
    put("cf:selidx", 1)
    put("cf:sel.PROC", 1)
    snap("39 cf:selidx=1, cf:sel PROC", ["cf:sel"])
    field("39 cf:selidx=1, cf:sel PROC", "cf:sel.NLST")
    for name in ("cf:lo_neg", "cf:ai_big"):
        numeric_gets("40 out of range", name)
        c = chan(name)
        for tname, ft in (("CTRL_CHAR", dbr.CTRL_CHAR), ("CTRL_SHORT", dbr.CTRL_SHORT), ("CTRL_ENUM", dbr.CTRL_ENUM)):
            for k, v in md(c, ft).items():
                obs[f"40 out of range|{name}|{tname}.{k}"] = v

    # ---- monitors: what a client subscribed with DBE_VALUE, DBE_LOG or DBE_ALARM receives
    # (MDEL/ADEL deadbands, HYST, alarm transitions), counted per subscription
    events = {}

    def subscribe(name, mask):
        c = chan(name)
        key = (name, mask)
        events[key] = []

        def cb(pvname=None, value=None, **kw):
            events[key].append(norm(value))
        h = ca.create_subscription(c, use_time=False, mask=mask, callback=cb)
        return h

    masks = {"DBE_VALUE": dbr.DBE_VALUE, "DBE_LOG": dbr.DBE_LOG, "DBE_ALARM": dbr.DBE_ALARM}
    mon_pvs = ["cf:mon_ai", "cf:mon_calc", "cf:mon_li", "cf:mon_hyst"]
    subs = [subscribe(n, m) for n in mon_pvs for m in masks.values()]
    ca.poll(0.5)
    time.sleep(0.5)
    for v in (0.5, 1.5, 1.8, 2.2, 4.0, 3.6, 9.0, 7.5, 4.8, 0.0):
        put("cf:mon_src", v)
    for n in mon_pvs:
        for mn, m in masks.items():
            obs[f"41 monitors|{n}|{mn} events (values)"] = events[(n, m)]
    snap("41 monitors", mon_pvs)
    for s_ in subs:
        ca.clear_subscription(s_[2])

    # ---- IVOA: an output whose alarm is INVALID (Continue normally / Don't drive / Set to IVOV)
    put("cf:ivoa_src", 12.0)
    snap("42 IVOA, input INVALID", ["cf:ivoa_cont", "cf:ivoa_hold", "cf:ivoa_set", "cf:ivoa_out1",
                                    "cf:ivoa_out2", "cf:ivoa_out3"])
    put("cf:ivoa_src", 3.0)
    snap("43 IVOA, input valid again", ["cf:ivoa_cont", "cf:ivoa_hold", "cf:ivoa_set", "cf:ivoa_out1",
                                        "cf:ivoa_out2", "cf:ivoa_out3"])

    # ---- SDLY: the simulated read ends after the delay (0.3 s); the put-callback waits for it
    put("cf:ai_sdly.PROC", 1, wait=False)
    field("44 cf:ai_sdly PROC, at once", "cf:ai_sdly.PACT")
    time.sleep(0.6)
    ca.poll(0.1)
    snap("45 cf:ai_sdly, 0.9 s later", ["cf:ai_sdly"])

    # ---- every field of every record type (the field list of softIoc.dbd): defaults as
    # DBR_STRING with the native type and count, then a put of one value per settable field
    sweep = json.loads(os.environ.get("CF_SWEEP", "null") or "null")
    if sweep:
        put_cb_type = ctypes.CFUNCTYPE(None, Args)
        done = {}

        def on_put(a):
            done["r"] = a.status
        pcb = put_cb_type(on_put)
        put_cb = libca["ca_array_put_callback"]
        put_cb.argtypes = [ctypes.c_long, ctypes.c_ulong, ctypes.c_void_p, ctypes.c_void_p,
                           put_cb_type, ctypes.c_void_p]

        def raw_put_string(name, text):
            c = chan(name)
            if c is None:
                return "NOT CONNECTED"
            buf = ctypes.create_string_buffer(text.encode(), 40)
            done.clear()
            st = put_cb(dbr.STRING, 1, c.value if hasattr(c, "value") else c, buf, pcb, None)
            if st != 1:
                return f"request {ca_message(st).decode()}"
            libca.ca_flush_io()
            t0 = time.time()
            while "r" not in done and time.time() - t0 < 1.5:
                ca.poll(0.01)
            return ca_message(done["r"]).decode() if "r" in done else "no callback"

        names = []
        for rtype, fields in sweep:
            for fname, dbf, settable in fields:
                names += [f"cf:t:{rtype}.{fname}", f"cf:p:{rtype}.{fname}"]
        for n in names:  # create all channels first: one search round for all
            if n not in chids:
                chids[n] = ca.create_channel(n, connect=False, auto_cb=False)
        t0 = time.time()  # a NOACCESS field never connects: wait for the rest, not for each
        while time.time() - t0 < 8 and not all(ca.isConnected(chids[n]) for n in names):
            ca.poll(0.2)
        for n in names:
            if not ca.isConnected(chids[n]):
                chids[n] = None
        progress("46 defaults")
        for rtype, fields in sweep:
            for fname, dbf, settable in fields:
                n = f"cf:t:{rtype}.{fname}"
                c = chids[n]
                key = f"46 defaults|cf:t:{rtype}|{fname}"
                if c is None:
                    obs[key] = "NOT CONNECTED"
                    continue
                obs[key + " type/count"] = f"{dbr.Name(ca.field_type(c)) if hasattr(dbr, 'Name') else ca.field_type(c)}/{ca.element_count(c)}"
                v = ca.get(c, ftype=dbr.STRING, timeout=3.0)
                obs[key] = norm(v)
        values = {"DBF_STRING": "ab", "DBF_MENU": "1", "DBF_ENUM": "1", "DBF_INLINK": "2",
                  "DBF_OUTLINK": "2", "DBF_FWDLINK": "", "DBF_FLOAT": "2.5", "DBF_DOUBLE": "2.5"}
        progress("47 put")
        for rtype, fields in sweep:
            progress(f"47 put {rtype}")
            for fname, dbf, settable in fields:
                # DISP would refuse every later put; the scan and device fields move the record
                if not settable or fname in ("PROC", "DTYP", "SCAN", "PHAS", "EVNT", "PRIO", "TPRO", "DISP"):
                    continue
                n = f"cf:p:{rtype}.{fname}"
                key = f"47 put|cf:p:{rtype}|{fname}"
                text = values.get(dbf, "3")
                obs[key + f" put {text!r}"] = raw_put_string(n, text)
                c = chids[n]
                if c is not None:
                    obs[key + " then"] = norm(ca.get(c, ftype=dbr.STRING, timeout=3.0))

    with open(out_path, "w") as f:
        json.dump(obs, f, indent=0)


# ---------------------------------------------------------------------------------------------
# driver side


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def observe(label, cmd):
    port = free_port()
    env = dict(os.environ, EPICS_CAS_SERVER_PORT=str(port), EPICS_CA_SERVER_PORT=str(port),
               EPICS_CAS_INTF_ADDR_LIST="127.0.0.1", EPICS_CAS_AUTO_BEACON_ADDR_LIST="NO",
               EPICS_CAS_BEACON_ADDR_LIST="127.0.0.1:9")
    log = tempfile.NamedTemporaryFile("w+", suffix=f"-{label}.log", delete=False)
    srv = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        for _ in range(100):
            with open(log.name) as f:
                t = f.read()
            if "ready:" in t or "iocRun: All initialization complete" in t:
                break
            if srv.poll() is not None:
                raise SystemExit(f"{label} exited: {t}")
            time.sleep(0.1)
        out = tempfile.NamedTemporaryFile(suffix=f"-{label}.json", delete=False).name
        cenv = dict(os.environ, EPICS_CA_ADDR_LIST=f"127.0.0.1:{port}", EPICS_CA_AUTO_ADDR_LIST="NO")
        subprocess.run([sys.executable, os.path.abspath(__file__), "--client", out], env=cenv, check=True)
        with open(out) as f:
            return json.load(f)
    finally:
        srv.terminate()
        try:
            srv.wait(5)
        except subprocess.TimeoutExpired:
            srv.kill()


def same(a, b):
    if isinstance(a, float) and isinstance(b, (int, float)) or isinstance(b, float) and isinstance(a, (int, float)):
        return a == b or abs(a - b) <= 1e-9 * max(1.0, abs(a), abs(b))
    return a == b


def fmt(v):
    if isinstance(v, list):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    if isinstance(v, str):
        return repr(v)
    return str(v)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--client")
    ap.add_argument("--beamctl", default=os.path.join(ROOT, "build/release/beamctl"))
    ap.add_argument("--softioc", default=os.environ.get("SOFTIOC"))
    ap.add_argument("--md", help="write the comparison as a markdown table")
    ap.add_argument("--dbd", help="expanded .dbd with the record types to sweep (default: softIoc's)")
    ap.add_argument("--json", help="write both observation sets")
    a = ap.parse_args()
    if a.client:
        return client(a.client)
    dbs = ["-d", DB, "-d", DB_ARRAYS, "-d", DB_41, "-d", DB_MON]
    dbd = a.dbd or (a.softioc and os.path.join(os.path.dirname(a.softioc), "..", "..", "dbd", "softIoc.dbd"))
    if dbd and os.path.exists(dbd):  # every field of every record type: base's own list
        sweep = dbd_sweep(dbd)
        path = tempfile.NamedTemporaryFile(suffix="-sweep.db", delete=False).name
        sweep_db(sweep, path)
        dbs += ["-d", path]
        os.environ["CF_SWEEP"] = json.dumps(sweep)
    bc = observe("beamctl", [a.beamctl, "softioc", "-S"] + dbs)
    if not a.softioc:
        for k, v in bc.items():
            print(k, "=", fmt(v))
        return
    si = observe("softIoc", [a.softioc, "-S"] + dbs)
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"beamctl": bc, "softIoc": si}, f, indent=0)
    keys = list(si) + [k for k in bc if k not in si]
    diff, match = [], 0
    for k in keys:
        x, y = bc.get(k, "(absent)"), si.get(k, "(absent)")
        if same(x, y):
            match += 1
        else:
            diff.append((k, x, y))
    print(f"{len(keys)} items compared: {match} match, {len(diff)} differ")
    lines = ["| step | PV | item | beamctl | softIoc |", "|---|---|---|---|---|"]
    for k, x, y in diff:
        step, pv, item = k.split("|")
        lines.append(f"| {step} | `{pv}` | {item} | `{fmt(x)}` | `{fmt(y)}` |")
    print("\n".join(lines))
    if a.md:
        with open(a.md, "w") as f:
            f.write(f"{len(keys)} items compared: {match} match, {len(diff)} differ\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
