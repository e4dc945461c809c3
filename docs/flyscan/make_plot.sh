#!/usr/bin/env bash
# Runs the spiral fly scan of docs/flyscan.md (examples/flyscan/ioc.yaml, 39 mm of arc at 1 mm/s,
# about 45 s) on a free CA port with pyepics, then plots its file into docs/flyscan/spiral_triggers.png.
#   bash docs/flyscan/make_plot.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
BEAMCTL=${BEAMCTL_BIN:-$PWD/build/release/beamctl}
PORT=${PORT:-$((20000 + RANDOM % 20000))}
out=$(mktemp -d)
EPICS_CAS_SERVER_PORT=$PORT EPICS_CAS_INTF_ADDR_LIST=127.0.0.1 "$BEAMCTL" run examples/flyscan/ioc.yaml > "$out/ioc.log" 2>&1 &
ioc=$!
trap 'kill $ioc 2>/dev/null; wait $ioc 2>/dev/null || true' EXIT
EPICS_CA_ADDR_LIST=127.0.0.1:$PORT EPICS_CA_AUTO_ADDR_LIST=NO OUT=$out /usr/bin/python3 - <<'PY'
import os, time, epics
for _ in range(100):
    if epics.caget("FLY:PCAP:ACTIVE", timeout=0.5) is not None:
        break
epics.caput("FLY:PCAP:FILE_PATH", os.environ["OUT"], wait=True)
epics.caput("FLY:PCAP:ARM", 1, wait=True)
time.sleep(0.5)
epics.caput("FLY:PCOMP1:ENABLE", 1, wait=True)
epics.caput("FLY:PCOMP2:ENABLE", 1, wait=True)
epics.caput("FLY:SpiralL", 39, wait=True, timeout=90)
epics.caput("FLY:PCAP:DISARM", 1, wait=True)
for _ in range(100):
    if epics.caget("FLY:PCAP:FILES") == 1:
        break
    time.sleep(0.1)
print(epics.caget("FLY:PCAP:FULL_FILE_NAME", as_string=True), epics.caget("FLY:PCAP:ROWS_WRITTEN"), "rows,",
      epics.caget("FLY:PCAP:ROWS_DROPPED"), "dropped")
PY
/usr/bin/python3 docs/flyscan/plot_spiral.py "$out/flyscan_0001.h5" docs/flyscan/spiral_triggers.png
