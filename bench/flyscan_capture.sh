#!/usr/bin/env bash
# The capture path against the disk it writes to, in one run: dd's sequential write rate (1 GiB,
# fdatasync included) in DIR, then bench_flyscan_capture in the same DIR: PCOMP cost, 64 signals
# at 10 kHz for SECS seconds (rows lost must be 0), and the HDF5 layer's rate unpaced (fsync
# included). The issue's target: the HDF5 layer at >= 50 % of dd's rate.
#   bash bench/flyscan_capture.sh [DIR=/tmp] [SECS=60] [UNPACED_ROWS=2000000]
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=${1:-/tmp}
SECS=${2:-60}
ROWS=${3:-2000000}
BIN=${BENCH_BIN:-$PWD/build/release/bench/bench_flyscan_capture}
f="$DIR/bench_dd_$$.bin"
echo "disk: $(df -h "$DIR" | tail -1 | awk '{print $1, $2}')"
dd if=/dev/zero of="$f" bs=1M count=1024 conv=fdatasync 2>&1 | tail -1 | sed 's/^/dd 1 GiB, fdatasync: /'
rm -f "$f"
"$BIN" "$DIR" "$SECS" "$ROWS"
