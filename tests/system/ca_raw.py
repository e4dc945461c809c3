"""A minimal Channel Access client over raw sockets, written from ca-protocol.md, for tests that
need to see the exact bytes (error replies, status fields, malformed input) that libca hides."""

import math
import socket
import struct
import time

# commands (ca-protocol.md §3)
VERSION, EVENT_ADD, EVENT_CANCEL, READ, WRITE, SEARCH = 0, 1, 2, 3, 4, 6
EVENTS_OFF, EVENTS_ON, READ_SYNC, ERROR, CLEAR_CHANNEL, RSRV_IS_UP = 8, 9, 10, 11, 12, 13
NOT_FOUND, READ_NOTIFY, CREATE_CHAN, WRITE_NOTIFY = 14, 15, 18, 19
CLIENT_NAME, HOST_NAME, ACCESS_RIGHTS, ECHO, CREATE_CH_FAIL, SERVER_DISCONN = 20, 21, 22, 23, 26, 27

# ECA codes (§4)
ECA_NORMAL, ECA_ALLOCMEM, ECA_TOLARGE, ECA_BADTYPE, ECA_INTERNAL = 1, 48, 72, 114, 142
ECA_GETFAIL, ECA_PUTFAIL, ECA_BADCOUNT, ECA_BADSTR, ECA_BADMONID = 152, 160, 176, 186, 242
ECA_NORDACCESS, ECA_NOWTACCESS = 368, 376

DBE_VALUE, DBE_LOG, DBE_ALARM, DBE_PROPERTY = 1, 2, 4, 8

# DBR base types
STRING, SHORT, FLOAT, ENUM, CHAR, LONG, DOUBLE = range(7)
STS_DOUBLE, TIME_STRING, TIME_SHORT, TIME_ENUM, TIME_LONG, TIME_DOUBLE = 13, 14, 15, 17, 19, 20
GR_DOUBLE, CTRL_SHORT, CTRL_FLOAT, CTRL_ENUM, CTRL_CHAR, CTRL_LONG, CTRL_DOUBLE = 27, 29, 30, 31, 32, 33, 34
_FMT = {SHORT: ">h", FLOAT: ">f", ENUM: ">H", CHAR: ">B", LONG: ">i", DOUBLE: ">d"}
_VSIZE = {STRING: 40, SHORT: 2, FLOAT: 4, ENUM: 2, CHAR: 1, LONG: 4, DOUBLE: 8}
# (size, value offset) per DBR type id 0..34 (§5)
_SIZE = [40, 2, 4, 2, 1, 4, 8,
         44, 6, 8, 6, 6, 8, 16,
         52, 16, 16, 16, 16, 16, 24,
         44, 26, 44, 424, 20, 40, 72,
         44, 30, 52, 424, 22, 48, 88]
_OFF = [0] * 7 + [4, 4, 4, 4, 5, 4, 8] + [12, 14, 12, 14, 15, 12, 16] + \
       [4, 24, 40, 422, 19, 36, 64] + [4, 28, 48, 422, 21, 44, 80]

EPICS_EPOCH = 631152000  # POSIX seconds at 1990-01-01 UTC


def pad8(n):
    return (n + 7) & ~7


def dbr_payload_size(dtype, count):
    """Unpadded payload bytes for `count` elements of DBR type dtype (§5)."""
    base = dtype % 7 if dtype < 35 else None
    return _SIZE[dtype] + (max(count, 1) - 1) * _VSIZE[base]


def header(cmd, postsize=0, dtype=0, count=0, p1=0, p2=0, extended=None):
    """Pack a header; extended (24 bytes) when sizes need it or extended=True."""
    if extended is None:
        extended = postsize >= 0xFFFF or count >= 0xFFFF
    if extended:
        return struct.pack(">HHHHIIII", cmd, 0xFFFF, dtype, 0, p1, p2, postsize, count)
    return struct.pack(">HHHHII", cmd, postsize, dtype, count, p1, p2)


def message(cmd, payload=b"", dtype=0, count=0, p1=0, p2=0, pad=True, extended=None):
    if pad:
        payload = payload + b"\0" * (pad8(len(payload)) - len(payload))
    return header(cmd, len(payload), dtype, count, p1, p2, extended) + payload


def encode_values(dtype, values):
    """Plain DBR payload (unpadded) for a list of values."""
    if dtype == STRING:
        out = b""
        for v in values:
            b = v.encode() if isinstance(v, str) else bytes(v)
            out += b[:39].ljust(40, b"\0")
        return out
    fmt = _FMT[dtype]
    return b"".join(struct.pack(fmt, v) for v in values)


def decode(dtype, count, payload):
    """Decode any DBR type 0..34 into a dict: value (list), status, severity, stamp, meta."""
    base = dtype % 7
    kind = dtype // 7  # 0 plain, 1 STS, 2 TIME, 3 GR, 4 CTRL
    out = {"dtype": dtype, "count": count}
    if kind >= 1:
        out["status"], out["severity"] = struct.unpack_from(">hh", payload, 0)
    if kind == 2:
        out["secs"], out["nsec"] = struct.unpack_from(">II", payload, 4)
    if kind >= 3 and base != STRING:
        nlim = 6 if kind == 3 else 8
        names = ["upper_disp", "lower_disp", "upper_alarm", "upper_warning", "lower_warning",
                 "lower_alarm", "upper_ctrl", "lower_ctrl"][:nlim]
        if base == ENUM:
            no_str = struct.unpack_from(">h", payload, 4)[0]
            out["no_str"] = no_str
            out["strs"] = [payload[6 + 26 * i:6 + 26 * (i + 1)].split(b"\0")[0].decode("latin-1")
                           for i in range(16)]
        elif base in (FLOAT, DOUBLE):
            out["precision"] = struct.unpack_from(">h", payload, 4)[0]
            out["units"] = payload[8:16].split(b"\0")[0].decode("latin-1")
            fmt = _FMT[base]
            vs = _VSIZE[base]
            for i, n in enumerate(names):
                out[n] = struct.unpack_from(fmt, payload, 16 + i * vs)[0]
        else:
            out["units"] = payload[4:12].split(b"\0")[0].decode("latin-1")
            fmt = _FMT[base]
            vs = _VSIZE[base]
            for i, n in enumerate(names):
                out[n] = struct.unpack_from(fmt, payload, 12 + i * vs)[0]
    off = _OFF[dtype]
    vals = []
    for i in range(count):
        if base == STRING:
            raw = payload[off + 40 * i: off + 40 * (i + 1)]
            vals.append(raw.split(b"\0")[0].decode("latin-1"))
        else:
            vals.append(struct.unpack_from(_FMT[base], payload, off + i * _VSIZE[base])[0])
    out["value"] = vals
    return out


class Msg:
    __slots__ = ("cmd", "postsize", "dtype", "count", "p1", "p2", "payload", "raw_header")

    def __init__(self, cmd, postsize, dtype, count, p1, p2, payload, raw_header):
        self.cmd, self.postsize, self.dtype, self.count = cmd, postsize, dtype, count
        self.p1, self.p2, self.payload, self.raw_header = p1, p2, payload, raw_header

    def __repr__(self):
        return (f"Msg(cmd={self.cmd}, size={self.postsize}, dtype={self.dtype}, count={self.count}, "
                f"p1={self.p1:#x}, p2={self.p2:#x}, payload={self.payload[:64]!r})")

    def error_text(self):
        """For ERROR: the NUL-terminated text after the embedded request header."""
        hdr_len = 24 if struct.unpack_from(">H", self.payload, 2)[0] == 0xFFFF else 16
        return self.payload[hdr_len:].split(b"\0")[0].decode("latin-1")

    def error_request(self):
        """For ERROR: the embedded request header as (cmd, postsize, dtype, count, p1, p2)."""
        cmd, size, dtype, count, p1, p2 = struct.unpack_from(">HHHHII", self.payload, 0)
        if size == 0xFFFF:
            size, count = struct.unpack_from(">II", self.payload, 16)
        return cmd, size, dtype, count, p1, p2


class ClosedError(Exception):
    pass


class Circuit:
    """One TCP circuit. recv() returns Msg; raises ClosedError when the server closes."""

    def __init__(self, host, port, timeout=5.0, rcvbuf=None, handshake=True, user="tester",
                 hostname="localhost", priority=0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.settimeout(timeout)
        self.sock.connect((host, port))
        self.buf = b""
        self.next_id = 1
        self.server_version = None
        if handshake:
            self.sock.sendall(message(VERSION, dtype=priority, count=13)
                              + message(HOST_NAME, hostname.encode() + b"\0")
                              + message(CLIENT_NAME, user.encode() + b"\0"))
            m = self.recv(timeout)
            assert m.cmd == VERSION, f"server's first message should be VERSION, got {m}"
            self.server_version = m

    def close(self):
        try:
            self.sock.close()
        except OSError:
            pass

    def __enter__(self):
        return self

    def __exit__(self, *a):
        self.close()

    def send(self, data):
        self.sock.sendall(data)

    def _fill(self, n, deadline):
        while len(self.buf) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                raise socket.timeout(f"timed out waiting for {n} bytes (have {len(self.buf)})")
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(max(65536, n - len(self.buf)))
            except ConnectionResetError:
                raise ClosedError("connection reset")
            if not chunk:
                raise ClosedError(f"closed by server (buffered {len(self.buf)} bytes)")
            self.buf += chunk

    def recv(self, timeout=5.0):
        deadline = time.monotonic() + timeout
        self._fill(16, deadline)
        cmd, size, dtype, count, p1, p2 = struct.unpack_from(">HHHHII", self.buf, 0)
        hlen = 16
        if size == 0xFFFF:
            self._fill(24, deadline)
            size, count = struct.unpack_from(">II", self.buf, 16)
            hlen = 24
        self._fill(hlen + size, deadline)
        raw_header = self.buf[:hlen]
        payload = self.buf[hlen:hlen + size]
        self.buf = self.buf[hlen + size:]
        return Msg(cmd, size, dtype, count, p1, p2, payload, raw_header)

    def recv_cmd(self, cmd, timeout=5.0, skip=(ACCESS_RIGHTS,)):
        """Next message, skipping the `skip` commands; asserts its command."""
        deadline = time.monotonic() + timeout
        while True:
            m = self.recv(max(0.0, deadline - time.monotonic()))
            if m.cmd in skip and m.cmd != cmd:
                continue
            assert m.cmd == cmd, f"expected command {cmd}, got {m}"
            return m

    def expect_closed(self, timeout=5.0):
        """Read (and return) messages until the server closes; fails on timeout."""
        got = []
        deadline = time.monotonic() + timeout
        try:
            while True:
                got.append(self.recv(max(0.001, deadline - time.monotonic())))
        except ClosedError:
            return got
        except socket.timeout:
            raise AssertionError(f"server did not close the circuit within {timeout} s; got {got}")

    def new_id(self):
        self.next_id += 1
        return self.next_id

    # --- requests ---------------------------------------------------------------------------
    def create(self, name, cid=None, timeout=5.0):
        """CREATE_CHAN; returns dict(cid, sid, dtype, count, access) or None on CREATE_CH_FAIL."""
        cid = cid if cid is not None else self.new_id()
        self.send(message(CREATE_CHAN, name.encode() + b"\0", p1=cid, p2=13))
        access = None
        deadline = time.monotonic() + timeout
        while True:
            m = self.recv(max(0.0, deadline - time.monotonic()))
            if m.cmd == ACCESS_RIGHTS and m.p1 == cid:
                access = m.p2
                continue
            if m.cmd == CREATE_CH_FAIL and m.p1 == cid:
                return None
            if m.cmd == CREATE_CHAN and m.p1 == cid:
                return {"cid": cid, "sid": m.p2, "dtype": m.dtype, "count": m.count,
                        "access": access}
            raise AssertionError(f"unexpected reply to CREATE_CHAN {name}: {m}")

    def read(self, ch, dtype=None, count=None, timeout=5.0):
        """READ_NOTIFY; returns (Msg, decoded dict)."""
        dtype = ch["dtype"] if dtype is None else dtype
        count = ch["count"] if count is None else count
        ioid = self.new_id()
        self.send(message(READ_NOTIFY, dtype=dtype, count=count, p1=ch["sid"], p2=ioid))
        m = self.recv_cmd(READ_NOTIFY, timeout)
        assert m.p2 == ioid, f"READ_NOTIFY reply for ioid {m.p2}, expected {ioid}"
        return m, decode(m.dtype, m.count, m.payload)

    def write(self, ch, values, dtype=None):
        dtype = ch["dtype"] if dtype is None else dtype
        values = list(values) if isinstance(values, (list, tuple)) else [values]
        self.send(message(WRITE, encode_values(dtype, values), dtype=dtype, count=len(values),
                          p1=ch["sid"], p2=ch["cid"]))

    def write_notify(self, ch, values, dtype=None, timeout=10.0):
        """WRITE_NOTIFY; returns the reply Msg (p1 = ECA status)."""
        dtype = ch["dtype"] if dtype is None else dtype
        values = list(values) if isinstance(values, (list, tuple)) else [values]
        ioid = self.new_id()
        self.send(message(WRITE_NOTIFY, encode_values(dtype, values), dtype=dtype,
                          count=len(values), p1=ch["sid"], p2=ioid))
        m = self.recv_cmd(WRITE_NOTIFY, timeout)
        assert m.p2 == ioid
        return m

    def subscribe(self, ch, mask=DBE_VALUE | DBE_ALARM, dtype=None, count=None, subid=None):
        dtype = ch["dtype"] if dtype is None else dtype
        count = ch["count"] if count is None else count
        subid = subid if subid is not None else self.new_id()
        self.send(message(EVENT_ADD, struct.pack(">fffHH", 0, 0, 0, mask, 0), dtype=dtype,
                          count=count, p1=ch["sid"], p2=subid))
        return subid

    def echo(self, timeout=5.0):
        self.send(message(ECHO))
        return self.recv_cmd(ECHO, timeout)


def udp_search(port, names, host="127.0.0.1", timeout=2.0, reply_flag=10, seq=0x1234,
               bind_host="127.0.0.1"):
    """Send one VERSION+SEARCH datagram; returns list of (Msg list per datagram) received."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((bind_host, 0))
    s.settimeout(0.2)
    data = message(VERSION, dtype=0, count=13, p1=seq)
    for i, name in enumerate(names):
        data += message(SEARCH, name.encode() + b"\0", dtype=reply_flag, count=13,
                        p1=1000 + i, p2=1000 + i)
    s.sendto(data, (host, port))
    datagrams = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            pkt, addr = s.recvfrom(65536)
        except socket.timeout:
            continue
        datagrams.append(parse_datagram(pkt))
    s.close()
    return datagrams


def parse_datagram(pkt):
    msgs = []
    off = 0
    while off + 16 <= len(pkt):
        cmd, size, dtype, count, p1, p2 = struct.unpack_from(">HHHHII", pkt, off)
        msgs.append(Msg(cmd, size, dtype, count, p1, p2, pkt[off + 16: off + 16 + size],
                        pkt[off:off + 16]))
        off += 16 + size
    return msgs


def is_nan(x):
    return isinstance(x, float) and math.isnan(x)
