"""Whole-process write latency of the RCP bridge: a Channel Access put from a real client
(pyepics on libca) until the RCP's socket has the data packet, p50/p99 over N puts. Starts a
bus-less `beamctl run` with only the bridge, plays the RCP with a plain UDP socket (one AO object).
   /usr/bin/python3 bench/rcp_put_latency.py [N=2000]"""

import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
N = int(sys.argv[1]) if len(sys.argv) > 1 else 2000


def free_port(kind):
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


ca_port, rcp_port = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_DGRAM)
os.environ.update(EPICS_CA_ADDR_LIST="127.0.0.1", EPICS_CA_AUTO_ADDR_LIST="NO",
                  EPICS_CA_SERVER_PORT=str(ca_port), EPICS_CAS_SERVER_PORT=str(ca_port),
                  EPICS_CAS_INTF_ADDR_LIST="127.0.0.1")
import epics  # noqa: E402  (after the environment)

work = Path(tempfile.mkdtemp())
(work / "ioc.yaml").write_text(f'ioc: {{name: LAT}}\nbridges:\n  rcp: {{listen: 127.0.0.1, port: {rcp_port}, prefix: "LAT:"}}\n')
ioc = subprocess.Popen([str(ROOT / "build/release/beamctl"), "run", str(work / "ioc.yaml")],
                       stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
try:
    assert ioc.stdout.readline().startswith(b"ready:")
    rcp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rcp.bind(("127.0.0.1", 0))
    rcp.settimeout(2)
    name = b"Set".ljust(40, b"\0")
    obj = struct.pack("<BBBIHIH", 1, 2, 8, 0x7F000001, rcp.getsockname()[1], 0x7F000001, rcp_port) + name
    rcp.sendto((struct.pack("<dB", 0.0, 1) + b"lat".ljust(40, b"\0") + obj + b"\0").ljust(1000, b"\0"),
               ("127.0.0.1", rcp_port))
    pv = epics.PV("LAT:lat:Set")
    assert pv.wait_for_connection(5)
    lat = []
    for i in range(N):
        t0 = time.perf_counter()
        pv.put(float(i))
        rcp.recvfrom(2000)
        lat.append(time.perf_counter() - t0)
    lat.sort()
    print(f"CA put (pyepics) -> data packet at the RCP, {N} puts: p50 {lat[N // 2] * 1e6:.0f} us, "
          f"p99 {lat[N * 99 // 100] * 1e6:.0f} us, max {lat[-1] * 1e6:.0f} us")
finally:
    ioc.terminate()
    ioc.wait()
