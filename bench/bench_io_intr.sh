#!/usr/bin/env bash
# I/O Intr benchmark (bench/bench_io_intr.cpp: 10 000 bus entries changing every cycle at 1 kHz, in
# virtual time) and a reference for the cost of processing a record: beamctl softioc and (when
# SOFTIOC points at an EPICS softIoc binary) softIoc serve 10 000 `bi` records with SCAN ".1 second"
# (100 000 processings per second demanded) for S seconds, pinned to CPU ${SERVER_CPUS:-0};
# records processed per CPU second = processings / (utime+stime from /proc/PID/stat).
#   bash bench/bench_io_intr.sh [S=10]
#   SOFTIOC=/path/to/softIoc bash bench/bench_io_intr.sh
set -euo pipefail
cd "$(dirname "$0")/.."
S=${1:-10}
OUT=bench/out; mkdir -p "$OUT"
build/release/bench/bench_io_intr 1250 2000 2>/dev/null
N=10000
awk -v n=$N 'BEGIN { for (i = 0; i < n; i++) printf "record(bi, \"scan%05d\") { field(SCAN, \".1 second\") }\n", i }' > "$OUT/scan$N.db"
TCK=$(getconf CLK_TCK)
free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
export EPICS_CAS_INTF_ADDR_LIST=127.0.0.1 EPICS_CAS_AUTO_BEACON_ADDR_LIST=NO EPICS_CAS_BEACON_ADDR_LIST=127.0.0.1:9
measure() { # name command...
    local name=$1; shift
    local port; port=$(free_port)
    EPICS_CAS_SERVER_PORT=$port taskset -c "${SERVER_CPUS:-0}" "$@" -d "$OUT/scan$N.db" >"$OUT/$name-scan.log" 2>&1 </dev/null &
    local pid=$!
    for _ in $(seq 600); do
        grep -qE "ready:|iocRun: All initialization complete" "$OUT/$name-scan.log" 2>/dev/null && break
        sleep 0.1
    done
    sleep 2
    local c0; c0=$(awk '{print $14+$15}' /proc/$pid/stat)
    sleep "$S"
    local c1; c1=$(awk '{print $14+$15}' /proc/$pid/stat)
    kill $pid; wait $pid 2>/dev/null || true
    awk -v n=$N -v s="$S" -v c0="$c0" -v c1="$c1" -v tck="$TCK" -v name="$name" 'BEGIN {
        cpu = (c1 - c0) / tck; rate = n * 10 * s
        printf "%s: %d bi records at .1 second: %.3f CPU s per second, %.2f M records per CPU second\n", name, n, cpu / s, (cpu > 0 ? rate / cpu / 1e6 : 0) }'
}
measure "beamctl softioc" build/release/beamctl softioc -S
if [ -n "${SOFTIOC:-}" ]; then measure "EPICS softIoc" "$SOFTIOC" -S; fi
