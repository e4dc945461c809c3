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

# What a server sends a client: VERSION, ACCESS_RIGHTS + CREATE_CHAN replies, values (READ_NOTIFY,
# monitor updates of TIME/CTRL types), WRITE_NOTIFY, ERROR with the failing header, ECHO, a
# cancelled monitor, SERVER_DISCONN; and a UDP datagram ('U' first) of search replies and a beacon.
srv = msg(0, 0, 13)
srv += msg(22, 0, 0, 1, 3) + msg(18, 6, 1, 1, 101)
srv += msg(22, 0, 0, 2, 1) + msg(18, 0, 1, 2, 102)
srv += msg(15, 6, 1, 1, 7, struct.pack(">d", 1.5))
srv += msg(15, 20, 1, 1, 8, struct.pack(">hhIIi", 0, 0, 1000, 5, 0) + struct.pack(">d", 2.5))
srv += msg(15, 14, 1, 1, 9, struct.pack(">hhII", 4, 1, 1000, 5) + b"hello".ljust(40, b"\0"))
ctrl = struct.pack(">hhhh", 0, 0, 3, 0) + b"mm".ljust(8, b"\0") + struct.pack(">8d", 10, 0, 9, 8, 1, 0, 10, 0) + struct.pack(">d", 4)
srv += msg(15, 34, 1, 1, 10, ctrl)
srv += msg(1, 20, 3, 1, 5, struct.pack(">hhIIi", 0, 0, 1000, 5, 0) + struct.pack(">3d", 1, 2, 3))
srv += msg(19, 6, 1, 1, 11) + msg(19, 6, 1, 160, 12)
srv += msg(11, 0, 0, 1, 376, msg(4, 6, 1, 101, 1)[:16] + b"no write access\0")
srv += msg(23) + msg(1, 20, 1, 101, 5) + msg(27, 0, 0, 2, 0) + msg(26, 0, 0, 3, 0)
write("fuzz_ca_client", "server", srv)
write("fuzz_ca_client", "bad", msg(0, 0, 13) + msg(15, 20, 1, 1, 7, b"\0" * 8) + msg(99))
write("fuzz_ca_client", "udp", b"U" + msg(0, 1, 13, 7) + msg(6, 5064, 0, 0xFFFFFFFF, 1, struct.pack(">H", 13))
      + msg(6, 5070, 0, 0x7F000001, 2, struct.pack(">H", 13)) + msg(13, 13, 5064, 4, 0))
