#!/usr/bin/env bash
# The area detector against the disk it writes to, in one run (issue 16): dd's sequential write
# rate (600 MiB, fdatasync included) in DIR before and after bench_area_detector in the same DIR (render,
# NDStats, 1024 x 1024 UInt16 frames into HDF5 unpaced, fsync included; target >= 50 % of dd),
# then frames/s to a CA monitor client: an IOC with a 1024 x 1024 camera in Continuous mode at
# AcquirePeriod 0 and a pyepics monitor on image1:ArrayData for SECS seconds, with the server's CPU.
#   bash bench/area_detector.sh [DIR=/tmp] [FRAMES=300] [SECS=10]
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=${1:-/tmp}
FRAMES=${2:-300}
SECS=${3:-10}
BIN=${BENCH_BIN:-$PWD/build/release/bench/bench_area_detector}
BEAMCTL=${BEAMCTL_BIN:-$PWD/build/release/beamctl}
f="$DIR/bench_dd_$$.bin"
echo "disk: $(df -h "$DIR" | tail -1 | awk '{print $1, $2}')"
dd_rate() {
    dd if=/dev/zero of="$f" bs=2M count=300 conv=fdatasync 2>&1 | tail -1 | sed "s/^/dd 600 MiB, fdatasync ($1): /"
    rm -f "$f"
}
dd_rate before
"$BIN" "$DIR" "$FRAMES"
dd_rate after

# frames/s to a CA monitor client
work=$(mktemp -d)
trap 'kill $ioc 2>/dev/null || true; rm -rf "$work"' EXIT
sed -e "s#plant: plant.yaml#plant: $PWD/examples/bpm/plant.yaml#" -e "s#file: ../#file: $PWD/examples/#" \
    -e "s#size: \[320, 240\], pixel_size: 0.01#size: [1024, 1024], pixel_size: 0.003#" \
    -e "s#acquire_period: 0.05}#acquire_period: 0}#" examples/bpm/ioc.yaml > "$work/ioc.yaml"
. bench/ioc_under_test.sh
start_ioc "$work/ioc.yaml" "$work/ioc.log"
EPICS_CA_MAX_ARRAY_BYTES=20000000 \
/usr/bin/python3 - "$SECS" "$ioc" <<'PY'
import sys, time, epics
secs, pid = float(sys.argv[1]), int(sys.argv[2])
def cpu():  # the server's user + system time [s]
    f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / 100
P = "BPM:"
epics.caput(P + "cam1:ImageMode", "Continuous", wait=True)
got = []
data = epics.PV(P + "image1:ArrayData", auto_monitor=True, callback=lambda value=None, **kw: got.append(len(value)))
data.wait_for_connection(5)
epics.caput(P + "cam1:Acquire", 1)
time.sleep(1)
got.clear()
n0, c0, t0 = epics.caget(P + "cam1:ArrayCounter_RBV"), cpu(), time.time()
time.sleep(secs)
n1, c1, t1 = epics.caget(P + "cam1:ArrayCounter_RBV"), cpu(), time.time()
epics.caput(P + "cam1:Acquire", 0)
frames = (n1 - n0) / (t1 - t0)
print(f"CA monitor, 1024 x 1024 UInt16 (DBR_LONG on the wire, 4 MiB a frame): camera {frames:.1f} frames/s, "
      f"client received {len(got) / (t1 - t0):.1f} frames/s ({sum(got) * 4 / (t1 - t0) / 1e6:.0f} MB/s), "
      f"server CPU {100 * (c1 - c0) / (t1 - t0):.0f} % of a core")
PY
