#!/usr/bin/env python3
"""Writes seed inputs for the CA fuzz targets (valid client conversations as libca sends them)."""
import os, struct, sys

here = os.path.dirname(os.path.abspath(__file__))

def msg(cmd, dtype=0, count=0, p1=0, p2=0, payload=b""):
    payload += b"\0" * (-len(payload) % 8)
    return struct.pack(">HHHHII", cmd, len(payload), dtype, count, p1, p2) + payload

def name(s):
    return s.encode() + b"\0"

def write(target, fname, data):
    d = os.path.join(here, "corpus", target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, fname), "wb") as f:
        f.write(data)

hello = msg(0, 0, 13) + msg(20, payload=name("fuzzer")) + msg(21, payload=name("localhost"))
pvs = ["f:ai", "f:ao", "f:bi", "f:bo", "f:li", "f:lo", "f:mbbi", "f:mbbo", "f:si", "f:so",
       "f:wf", "f:ws", "f:wc", "f:ai.EGU", "f:ai.NAME$", "f:ai.RTYP", "f:ai.HIHI"]
conv = hello
for i, pv in enumerate(pvs):
    conv += msg(18, 0, 0, i + 1, 13, name(pv))
for sid in range(1, len(pvs) + 1):
    for t in (0, 6, 13, 20, 27, 34, 31, 37, 38):
        conv += msg(15, t, 0 if sid == 11 else 1, sid, 1000 + t)
    conv += msg(1, 20, 0, sid, 500 + sid, struct.pack(">fffHH", 0, 0, 0, 5, 0))
conv += msg(4, 6, 1, 1, 1, struct.pack(">d", 3.5))
conv += msg(19, 0, 1, 3, 77, b"On".ljust(40, b"\0"))
conv += msg(19, 6, 4, 11, 78, struct.pack(">4d", 1, 2, 3, 4))
conv += msg(8) + msg(4, 6, 1, 2, 1, struct.pack(">d", 9)) + msg(9)
conv += msg(2, 20, 1, 1, 501) + msg(12, 0, 0, 1, 1) + msg(23) + msg(10)
conv += msg(6, 10, 13, 0, 9, name("f:ao"))
write("fuzz_ca_circuit", "conversation", conv)
write("fuzz_ca_circuit", "extended", msg(0, 0, 13) + msg(18, 0, 0, 1, 13, name("f:wf")) +
      struct.pack(">HHHHIIII", 19, 0xFFFF, 6, 0, 1, 5, 64 * 8, 64) + b"\0" * 512)
write("fuzz_ca_circuit", "bad", msg(0, 0, 13) + msg(77) + msg(1, 99, 1, 5, 5, b"\0" * 16))

search = msg(0, 0, 13, 7)
for i, pv in enumerate(pvs + ["nope", "f:ai.NOPE"]):
    search += msg(6, 5, 13, i, i, name(pv))
write("fuzz_ca_search", "search", search)
write("fuzz_ca_search", "do_reply", msg(0, 0, 13) + msg(6, 10, 13, 1, 1, name("missing")))
