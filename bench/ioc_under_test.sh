# Sourced by the benchmarks that measure a running IOC (bench/area_detector.sh, bench/mca_server.sh).
# start_ioc CONFIG LOG: `beamctl run CONFIG` in the background on a CA port picked at random
# (20000..39999), output to LOG, waiting (10 s at most) for its ready line. Sets $ioc (its pid) and
# exports EPICS_CA_ADDR_LIST / EPICS_CA_AUTO_ADDR_LIST for the client that follows. The caller's
# EXIT trap kills $ioc.
start_ioc() {
    local port=$((20000 + RANDOM % 20000))
    EPICS_CAS_SERVER_PORT=$port "${BEAMCTL:-$PWD/build/release/beamctl}" run "$1" --shell-socket none > "$2" 2>&1 &
    ioc=$!
    for _ in $(seq 50); do grep -q '^ready' "$2" && break; sleep 0.2; done
    grep -q '^ready' "$2" || { echo "the IOC did not start:"; cat "$2"; exit 1; }
    export EPICS_CA_ADDR_LIST=127.0.0.1:$port EPICS_CA_AUTO_ADDR_LIST=NO
}
