#!/usr/bin/env bash
# CA server benchmark: serves N double PVs (bench:00000..) with beamctl and, when SOFTIOC points
# at an EPICS softIoc binary, with softIoc too, and loads each with the same script
# (../shared/tools/bench-ca.sh, real libca via cabench) in the same run.
#   bash bench/run.sh [N=10000] [secs=10]        SOFTIOC=/path/to/softIoc bash bench/run.sh
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-10000}; S=${2:-10}
TOOLS=${BEAMCTL_TOOLS:-../shared/tools}
OUT=bench/out; mkdir -p "$OUT"
CABENCH=$OUT/cabench
if [ ! -x "$CABENCH" ]; then
    gcc -O2 -o "$CABENCH" "$TOOLS/cabench.c" /usr/lib/x86_64-linux-gnu/libca.so.4.13.5 \
        /usr/lib/x86_64-linux-gnu/libCom.so.3.17.6 -lm
fi
DB=$OUT/bench$N.db
awk -v n="$N" 'BEGIN { for (i = 0; i < n; i++) printf "record(ao, \"bench:%05d\") { field(PREC, \"3\") }\n", i }' > "$DB"

free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
export EPICS_CAS_INTF_ADDR_LIST=127.0.0.1 EPICS_CAS_AUTO_BEACON_ADDR_LIST=NO EPICS_CAS_BEACON_ADDR_LIST=127.0.0.1:9

run_one() { # name, command...
    local name=$1; shift
    local port; port=$(free_port)
    EPICS_CAS_SERVER_PORT=$port EPICS_CA_SERVER_PORT=$port taskset -c "${SERVER_CPUS:-0}" "$@" >"$OUT/$name.log" 2>&1 </dev/null &
    local pid=$!
    for _ in $(seq 100); do
        grep -qE "ready:|iocRun: All initialization complete" "$OUT/$name.log" && break
        sleep 0.1
    done
    echo "######## $name"
    CABENCH=$CABENCH CLIENT_CPUS=${CLIENT_CPUS:-1} bash "$TOOLS/bench-ca.sh" "$pid" "$port" "$N" "$S"
    kill "$pid"; wait "$pid" 2>/dev/null || true
}

# Resident memory with one PV (the program's own footprint), to derive memory per PV.
DB1=$OUT/bench1.db
echo 'record(ao, "bench:00000") { field(PREC, "3") }' > "$DB1"
rss_one() { # name, command...
    local name=$1; shift
    local port; port=$(free_port)
    EPICS_CAS_SERVER_PORT=$port EPICS_CA_SERVER_PORT=$port "$@" >"$OUT/$name-1.log" 2>&1 </dev/null &
    local pid=$!
    for _ in $(seq 100); do
        grep -qE "ready:|iocRun: All initialization complete" "$OUT/$name-1.log" && break
        sleep 0.1
    done
    sleep 0.5
    echo "######## $name with 1 PV: $(awk '/VmRSS/{print $2 " kB"}' /proc/$pid/status)"
    kill "$pid"; wait "$pid" 2>/dev/null || true
}

BIN=${BEAMCTL_BIN:-build/release/beamctl}
rss_one beamctl "$BIN" softioc "$DB1" | tee "$OUT/beamctl-1.txt"
run_one beamctl "$BIN" softioc "$DB" | tee "$OUT/beamctl.txt"
if [ -n "${SOFTIOC:-}" ]; then
    rss_one softIoc "$SOFTIOC" -S -d "$DB1" | tee "$OUT/softioc-1.txt"
    run_one softIoc "$SOFTIOC" -S -d "$DB" | tee "$OUT/softioc.txt"
fi
