#!/usr/bin/env bash
# Record-processing chain benchmark: beamctl softioc and (when SOFTIOC points at an EPICS softIoc
# binary) softIoc serve the same database of C copies of a 10-record chain (bench/db/chain.db,
# macro N), one server after the other, pinned to CPU ${SERVER_CPUS:-0}. A client pinned to CPU
# ${CLIENT_CPUS:-1} (cabench putff on Debian's real libca) puts DBR_DOUBLE to the head ao of H
# chains as fast as it can for S seconds; every put processes 10 records:
#   ao head -FLNK-> calc -FLNK-> calcout -OUT PP-> ao, -FLNK-> seq -LNK1 PP-> longout
#                                                             -LNK2 PP-> calc -FLNK-> calc -FLNK->
#   calcout -OUT PP-> calc tail (CALC "VAL+1": counts the chain processings)
# Chain processings are counted on the servers (sum of the tails), CPU from /proc/PID/stat
# (utime+stime) over the same interval. Memory per record: resident memory serving C copies
# minus serving 1 copy, over 10 (C-1) records.
# RATE=R paces the client to R rounds (puts to each of the H heads) per second, so that both
# servers see the same offered load (unpaced, a faster server gets more, smaller reads).
#   bash bench/bench_db_chain.sh [C=10000] [S=10] [H=1]
#   SOFTIOC=/path/to/softIoc bash bench/bench_db_chain.sh
#   RATE=40000 SOFTIOC=/path/to/softIoc bash bench/bench_db_chain.sh 10000 10 1
set -euo pipefail
cd "$(dirname "$0")/.."
C=${1:-10000}; S=${2:-10}; H=${3:-1}
TOOLS=${BEAMCTL_TOOLS:-../shared/tools}
OUT=bench/out; mkdir -p "$OUT"
CABENCH=$OUT/cabench
if [ ! -x "$CABENCH" ]; then
    gcc -O2 -o "$CABENCH" "$TOOLS/cabench.c" /usr/lib/x86_64-linux-gnu/libca.so.4.13.5 \
        /usr/lib/x86_64-linux-gnu/libCom.so.3.17.6 -lm
fi
PY=/usr/bin/python3
TCK=$(getconf CLK_TCK)
mkdb() { # copies -> file
    # one flat .db (both servers load it with -d): the template with N=00000, 00001, ...
    awk -v c="$1" 'NR==FNR { t = t $0 "\n"; next } END { for (i = 0; i < c; i++) { s = t; n = sprintf("%05d", i); gsub(/\$\(N\)/, n, s); printf "%s", s } }' \
        bench/db/chain.db /dev/null > "$OUT/chain$1.db"
}
mkdb "$C"; mkdb 1

free_port() { $PY -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
export EPICS_CAS_INTF_ADDR_LIST=127.0.0.1 EPICS_CAS_AUTO_BEACON_ADDR_LIST=NO EPICS_CAS_BEACON_ADDR_LIST=127.0.0.1:9
PID=; PORT=
start() { # name db command...
    local name=$1 db=$2; shift 2
    PORT=$(free_port)
    rm -f "$OUT/$name.log"  # not truncated by the background redirection yet when grep first looks
    EPICS_CAS_SERVER_PORT=$PORT EPICS_CA_SERVER_PORT=$PORT taskset -c "${SERVER_CPUS:-0}" "$@" "$db" \
        >"$OUT/$name.log" 2>&1 </dev/null &
    PID=$!
    for _ in $(seq 600); do
        grep -qE "ready:|iocRun: All initialization complete" "$OUT/$name.log" 2>/dev/null && break
        sleep 0.1
    done
    grep -qE "ready:|iocRun: All initialization complete" "$OUT/$name.log" || { echo "$name did not start"; exit 1; }
    sleep 1
}
stop() { kill "$PID"; wait "$PID" 2>/dev/null || true; }
cpu() { awk '{print $14+$15}' /proc/$PID/stat; }
rss() { awk '/VmRSS/{print $2}' /proc/$PID/status; }
tails() { # sum of the H tail counters
    EPICS_CA_ADDR_LIST=127.0.0.1:$PORT EPICS_CA_AUTO_ADDR_LIST=NO $PY -c '
import sys, epics
h = int(sys.argv[1])
v = epics.caget_many(["chain%05d:tail" % i for i in range(h)], timeout=5)
assert None not in v, "tail counters not readable"
print(int(sum(v)))' "$H"
}

run() { # name command...
    local name=$1; shift
    start "$name-1" "$OUT/chain1.db" "$@"; local r1; r1=$(rss); stop
    start "$name" "$OUT/chain$C.db" "$@"; local rc; rc=$(rss)
    local n0 c0 t0 n1 c1 t1
    n0=$(tails); c0=$(cpu); t0=$(date +%s.%N)
    EPICS_CA_ADDR_LIST=127.0.0.1:$PORT EPICS_CA_AUTO_ADDR_LIST=NO \
        taskset -c "${CLIENT_CPUS:-1}" "$CABENCH" putff "chain%05d:head" "$H" "$S" ${RATE:-} 2>/dev/null | grep -v connect
    n1=$(tails); c1=$(cpu); t1=$(date +%s.%N)
    local rl; rl=$(rss)
    stop
    awk -v name="$name" -v r1="$r1" -v rc="$rc" -v rl="$rl" -v c="$C" -v n="$((n1 - n0))" \
        -v cpu="$(( c1 - c0 ))" -v tck="$TCK" -v t0="$t0" -v t1="$t1" 'BEGIN {
        wall = t1 - t0; cs = cpu / tck
        printf "%s: %d chain processings in %.2f s = %.0f chains/s (%.0f records/s); server CPU %.2f s (%.0f %% of one core) = %.0f chains per CPU second\n",
               name, n, wall, n / wall, 10 * n / wall, cs, 100 * cs / wall, (cs > 0 ? n / cs : 0)
        printf "%s: RSS 1 chain %d kB, %d chains %d kB (after the run %d kB): %.3f kB per record\n",
               name, r1, c, rc, rl, (rc - r1) / (10 * (c - 1))
    }'
}

BIN=${BEAMCTL_BIN:-build/release/beamctl}
run beamctl "$BIN" softioc -S -d | tee "$OUT/chain-beamctl.txt"
if [ -n "${SOFTIOC:-}" ]; then
    run softIoc "$SOFTIOC" -S -d | tee "$OUT/chain-softioc.txt"
fi
