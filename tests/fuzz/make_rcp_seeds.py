#!/usr/bin/env python3
"""Writes seed inputs for fuzz_rcp_packet: chunks of [control byte][1000-byte RCP packet] (see the
header of fuzz_rcp_packet.cpp) with beacons, continuations and data packets that match the
application the target already knows ("fz" from 10.0.0.2:5000), and some malformed ones."""
import os, struct

here = os.path.dirname(os.path.abspath(__file__))
AI, AO, BI, BO, LI, LO, MOTOR = range(1, 8)
BOOL, I8, U8, I16, U16, I32, U32, F32, F64 = range(9)
FMT = {BOOL: "B", I8: "b", U8: "B", I16: "h", U16: "H", I32: "i", U32: "I", F32: "f", F64: "d"}


def name(s):
    return s.encode().ljust(40, b"\0")


def beacon(app, objects, continuation=False, ts=1.0):
    p = struct.pack("<dB", ts, 0x81 if continuation else 1) + name(app)
    for oid, otype, dtype, oname in objects:
        p += struct.pack("<BBBIHIH", oid, otype, dtype, 0x0A000002, 18066, 0x0A000001, 18065) + name(oname)
    return p.ljust(1000, b"\0")


def data(entries, ts=2.0):
    p = struct.pack("<d", ts)
    for oid, otype, dtype, oname, values in entries:
        p += struct.pack("<BBBH", oid, otype, dtype, len(values)) + name(oname)
        p += struct.pack("<%d%s" % (len(values), FMT[dtype]), *values)
    return p.ljust(1000, b"\0")


def chunk(packet, ctrl=0):
    return bytes([ctrl]) + packet


def write(fname, content):
    d = os.path.join(here, "corpus", "fuzz_rcp_packet")
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, fname), "wb") as f:
        f.write(content)


known = [(1, AI, F64, "a"), (2, AO, F32, "b"), (3, BI, BOOL, "c"), (4, BO, BOOL, "d"),
         (5, LI, I16, "e"), (6, LO, U8, "f"), (7, MOTOR, F64, "m"), (8, AI, I32, "w")]
values = data([(1, AI, F64, "a", [1.5]), (2, AO, F32, "b", [2.0]), (3, BI, BOOL, "c", [1]),
               (4, BO, BOOL, "d", [0]), (5, LI, I16, "e", [-3]), (6, LO, U8, "f", [7]),
               (7, MOTOR, F64, "m", [1.0, 0.0, 65.0, 0.0, 0.0]), (8, AI, I32, "w", [1, 2, 3, 4])])
moving = data([(7, MOTOR, F64, "m", [0.5, 1.0, 66.0, 0.0, 0.0])])
write("data", chunk(values) + chunk(values, 0x40) + chunk(moving) + chunk(values, 0x40))
write("silence", chunk(values) + chunk(values, 0x20) + chunk(values, 0x20) + chunk(values))
many = [(i, AI, F64, "s%d" % i) for i in range(1, 21)]
write("continuation", chunk(beacon("fz", many[:17])) + chunk(beacon("fz", many[17:], True), 0x10) +
      chunk(data([(18, AI, F64, "s18", [4.0])])))
changed = [(1, AO, F64, "a"), (9, LO, I32, "new"), (3, BI, BOOL, "c")]
write("change", chunk(values) + chunk(beacon("fz", changed), 0x20) +
      chunk(data([(9, LO, I32, "new", [5])])) + chunk(values, 0x20))
write("apps", chunk(beacon("other", [(1, AI, F64, "x")]), 2) + chunk(data([(1, AI, F64, "x", [3.0])]), 2) +
      chunk(data([(1, AI, F64, "x", [3.0])]), 6) + chunk(beacon("fz", known), 4))
bad_type = bytearray(values)
bad_type[9] = 9
bad_count = bytearray(values)
bad_count[11:13] = struct.pack("<H", 900)
write("malformed", chunk(values[:500], 1) + chunk(bytes(bad_type)) + chunk(bytes(bad_count)) +
      chunk(data([(1, AI, F32, "a", [1.0])])) + chunk(data([(1, AI, F64, "zz", [1.0])])) +
      chunk(data([(99, AI, F64, "a", [1.0])])) + chunk(data([(1, AI, F64, "a", [1.0, 2.0])])))
