#!/usr/bin/env bash
# Highest sustainable EtherCAT cycle rate over a veth pair, master and simulator in separate
# processes: `beamctl sim --iface` serves a 40-terminal segment on one end of a veth pair inside a
# network namespace (pinned to SIM_CPU), `beamctl run` drives it through a raw link on the other
# end (RT thread pinned to RUN_CPU) at each engine rate for SECS seconds. Per rate: the round
# trip of every frame on the wire for 1 s (kernel timestamps on the master's end; [us]), `late` =
# frames back after the master's receive timeout (half a period) or not at all, and over CA the
# increase of m0-MissedFrames / m0-WkcErrors after the bus reached OP and m0-ThdLatMax [us].
# A rate is sustained when nothing was late, missed or wrong. The wire count matters: a frame
# that comes back late is read by the next cycle instead and MissedFrames no longer counts.
# Needs root (namespaces, raw sockets, SCHED_FIFO).
#   SIM_BUSY_POLL=1: `beamctl sim --busy-poll` (answers at once like hardware; default 0: it sleeps
#   in ppoll and pays the wake-up latency); MASTER_BUSY_POLL=1: `link: {busy_poll: true}`.
#   sudo bash bench/veth_rate.sh [SECS=5] [RATES="1000 2000 5000 10000 20000"]
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${1:-5}
RATES=${2:-"1000 2000 5000 10000 20000"}
BEAMCTL=${BEAMCTL_BIN:-$PWD/build/release/beamctl}
RUN_CPU=${RUN_CPU:-0}
SIM_CPU=${SIM_CPU:-1}
SIM_BUSY_POLL=${SIM_BUSY_POLL:-0}
MASTER_BUSY_POLL=${MASTER_BUSY_POLL:-0}
SIM_ARGS=(); [ "$SIM_BUSY_POLL" = 1 ] && SIM_ARGS=(--busy-poll)
MASTER_BP=false; [ "$MASTER_BUSY_POLL" = 1 ] && MASTER_BP=true
OUT=bench/out/veth; mkdir -p "$OUT"

TAG=$(printf "%06x" $((RANDOM * 32768 + RANDOM)))
NS=bcbench$TAG; MEND=bcm$TAG; SEND=bcs$TAG
SIM_PID=""
cleanup() {
    [ -n "$SIM_PID" ] && kill "$SIM_PID" 2>/dev/null && wait "$SIM_PID" 2>/dev/null
    ip link del "$MEND" 2>/dev/null || true
    ip netns del "$NS" 2>/dev/null || true
}
trap cleanup EXIT
ip netns add "$NS"
ip link add "$MEND" type veth peer name "$SEND" netns "$NS"
ip link set "$MEND" up
ip -n "$NS" link set "$SEND" up

# The 40-terminal segment of bench_ethercat.cpp.
MIX=(EL1008 EL2008 EL3104 EL4134 EL5101 EL7041 EL7211 EL5042 EL3102 EL4102 EL1252 EL2808 EL1008)
SLAVES="      - {position: 0, type: EK1100}"$'\n'
for i in $(seq 1 39); do SLAVES+="      - {position: $i, type: ${MIX[$(((i - 1) % 13))]}}"$'\n'; done
printf 'slaves:\n%s' "${SLAVES//      - /  - }" > "$OUT/sim40.yaml"

taskset -c "$SIM_CPU" ip netns exec "$NS" "$BEAMCTL" sim "$OUT/sim40.yaml" --iface "$SEND" "${SIM_ARGS[@]}" >"$OUT/sim.log" 2>&1 &
SIM_PID=$!
for _ in $(seq 50); do grep -q "ready:" "$OUT/sim.log" && break; sleep 0.1; done
grep -q "ready:" "$OUT/sim.log" || { cat "$OUT/sim.log"; exit 1; }

PORT=$(/usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
export EPICS_CAS_INTF_ADDR_LIST=127.0.0.1 EPICS_CAS_AUTO_BEACON_ADDR_LIST=NO EPICS_CAS_BEACON_ADDR_LIST=127.0.0.1:9
export EPICS_CAS_SERVER_PORT=$PORT EPICS_CA_ADDR_LIST=127.0.0.1:$PORT EPICS_CA_AUTO_ADDR_LIST=NO

echo "sim busy-poll: $SIM_BUSY_POLL, master busy-poll: $MASTER_BUSY_POLL, ${SECS} s per rate"
printf "%-9s %-7s %-8s %-8s %-8s %-6s %-7s %-7s %-8s %s\n" rate_hz frames rtt_p50 rtt_p99 rtt_max late missed wkc_err lat_max sustained
for R in $RATES; do
    cat > "$OUT/ioc$R.yaml" <<EOF
ioc: {name: VB, prefix: "VB$TAG:"}
engine: {rate_hz: $R, cpu: $RUN_CPU}
buses:
  - id: 0
    link: {type: raw, iface: $MEND, busy_poll: $MASTER_BP}
    slaves:
$SLAVES
EOF
    "$BEAMCTL" run "$OUT/ioc$R.yaml" >"$OUT/run$R.log" 2>&1 &
    RUN_PID=$!
    for _ in $(seq 100); do grep -q "ready:" "$OUT/run$R.log" && break; sleep 0.1; done
    /usr/bin/python3 - "VB$TAG:m0" "$SECS" "$R" "$MEND" <<'PY' 2>/dev/null || echo "$R: no answer over CA (see $OUT/run$R.log)"
import socket, statistics, struct, sys, time, epics
m, secs, rate, iface = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
get = lambda s: epics.caget(m + s, timeout=5)
t0 = time.time()
while get("-Stat-OK") != 1 and time.time() - t0 < 10:
    time.sleep(0.1)
time.sleep(0.5)  # past bring-up
miss0, wkc0 = get("-MissedFrames"), get("-WkcErrors")
# Wire round trips on the master's end for 1 s (kernel timestamps): each returning frame against
# the frame the master sent with the same datagram index, FIFO.
s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
s.setsockopt(socket.SOL_SOCKET, 33, 64 << 20)  # SO_RCVBUFFORCE
s.setsockopt(socket.SOL_SOCKET, 35, 1)         # SO_TIMESTAMPNS
s.bind((iface, 0))
s.settimeout(0.2)
frames, end = [], time.time() + 1.0
while time.time() < end:
    try:
        data, anc, _f, addr = s.recvmsg(64, 64)
    except socket.timeout:
        continue
    if data[12:14] != b"\x88\xa4":
        continue
    sec, ns = struct.unpack("qq", anc[0][2][:16])
    frames.append((sec * 1e9 + ns, addr[2] == 4, data[17]))  # time, outgoing, first datagram idx
s.close()
time.sleep(max(0.0, secs - 1.0))
miss, wkc = get("-MissedFrames") - miss0, get("-WkcErrors") - wkc0
sent, rtt, pending = 0, [], []
for t, out, idx in frames:
    if out:
        sent += 1
        pending.append((t, idx))
        continue
    while pending and pending[0][1] != idx:
        pending.pop(0)
    if pending:
        rtt.append((t - pending.pop(0)[0]) / 1000.0)
budget = 1e6 / rate / 2  # the master's receive timeout: half a period [us]
late = sum(1 for r in rtt if r > budget) + max(0, sent - len(rtt) - 1)
rtt.sort()
q = lambda f: rtt[min(len(rtt) - 1, int(f * len(rtt)))] if rtt else float("nan")
ok = miss == 0 and wkc == 0 and late == 0 and get("-Stat-OK") == 1
print(f"{rate:<9} {sent:<7} {q(0.5):<8.1f} {q(0.99):<8.1f} {q(1.0):<8.1f} {late:<6} {miss:<7} {wkc:<7} "
      f"{get('-ThdLatMax'):<8.1f} {'yes' if ok else 'NO'}")
PY
    kill "$RUN_PID"; wait "$RUN_PID" 2>/dev/null || true
done
