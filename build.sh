#!/usr/bin/env bash
# beamctl quick start. On a fresh Debian bookworm machine (as root):
#   bash build.sh demo    install what is missing, build, run the demo IOC
#   bash build.sh test    install what is missing, build, run every test
# Other verbs: deps, build, unit, system, fuzz, bench.
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(pwd)
JOBS=${JOBS:-$(nproc)}

# Debian packages the build, the tests and the demo need.
BUILD_PKGS="g++ cmake ninja-build pkgconf libcli11-dev libgtest-dev libgmock-dev libbenchmark-dev libyaml-cpp-dev libtinyxml2-dev libmuparser-dev libhdf5-dev libcminpack-dev"
# The client command that the demo prints (pyepics imports only under Debian's /usr/bin/python3).
DEMO_PKGS="python3 python3-pyepics"
TEST_PKGS="$DEMO_PKGS python3-pytest python3-numpy iproute2 procps clang-14 libclang-rt-14-dev tshark python3-h5py hdf5-tools python3-matplotlib python3-aiosmtpd"

deps() {
    local want="$BUILD_PKGS"
    [ "${1:-}" = test ] && want="$want $TEST_PKGS"
    [ "${1:-}" = demo ] && want="$want $DEMO_PKGS"
    local missing=""
    for p in $want; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
    done
    if [ -n "$missing" ]; then
        echo "== installing Debian packages:$missing"
        local SUDO=""
        [ "$(id -u)" = 0 ] || SUDO=sudo
        # tshark asks whether non-root users may capture: no (the tests capture as root).
        echo "wireshark-common wireshark-common/install-setuid boolean false" | $SUDO debconf-set-selections
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
    fi
    ca_repeater_link
}

# EPICS libca (pyepics) runs `caRepeater` from PATH when no CA repeater holds UDP port
# EPICS_CA_REPEATER_PORT (5065) and warns when there is none. As root, and when PATH has no
# caRepeater yet, link /usr/local/bin/caRepeater to this tree's beamctl, which serves as one.
ca_repeater_link() {
    [ "$(id -u)" = 0 ] || return 0
    command -v caRepeater >/dev/null 2>&1 && return 0
    mkdir -p /usr/local/bin
    ln -sfn "$ROOT/build/release/beamctl" /usr/local/bin/caRepeater
    echo "== /usr/local/bin/caRepeater -> $ROOT/build/release/beamctl (the CA repeater libca starts)"
}

build() { # preset [targets...] (default: everything)
    local preset=${1:-release}
    shift || true
    echo "== building ($preset${*:+: $*})"
    [ -f "build/$preset/build.ninja" ] || cmake --preset "$preset" >/dev/null
    cmake --build --preset "$preset" -j "$JOBS" ${*:+--target "$@"}
}

unit() {
    echo "== unit tests (release)"
    (cd build/release && ctest --output-on-failure -j "$JOBS")
    if [ "${BEAMCTL_SKIP_SANITIZE:-0}" != 1 ]; then
        build dev beamctl_unit_tests # only what the sanitized run needs (no app, no benchmarks)
        echo "== unit tests (ASan + UBSan)"
        (cd build/dev && ctest --output-on-failure -j "$JOBS")
    fi
}

fuzz() {
    # Builds the libFuzzer targets with clang and runs each for a short time (a smoke run;
    # longer campaigns: FUZZ_SECONDS=600 bash build.sh fuzz), JOBS targets at a time (each is one
    # process on one core).
    # only the targets and the libraries they link (not the rest of the engine)
    build fuzz $(cd tests/fuzz && ls fuzz_*.cpp | sed 's/\.cpp$//')
    local secs=${FUZZ_SECONDS:-20} batch=() failed=0
    mkdir -p build/fuzz/logs
    run_batch() {
        local pids=() t
        for t in "${batch[@]}"; do
            local name corpus
            name=$(basename "$t")
            corpus="tests/fuzz/corpus/$name"
            mkdir -p "build/fuzz/corpus/$name"
            "$t" -max_total_time="$secs" -print_final_stats=1 "build/fuzz/corpus/$name" \
                $( [ -d "$corpus" ] && echo "$corpus" ) >"build/fuzz/logs/$name.log" 2>&1 &
            pids+=($!)
        done
        local i
        for i in "${!batch[@]}"; do
            local name rc=0
            name=$(basename "${batch[$i]}")
            wait "${pids[$i]}" || rc=$?
            echo "== $name for ${secs}s"
            grep -E "stat::number_of_executed_units|Done|ERROR|SUMMARY" "build/fuzz/logs/$name.log" || true
            [ "$rc" = 0 ] || { echo "fuzz target $name failed (exit $rc; build/fuzz/logs/$name.log)"; failed=1; }
        done
        batch=()
    }
    for t in build/fuzz/tests/fuzz/fuzz_*; do
        [ -x "$t" ] || continue
        batch+=("$t")
        [ "${#batch[@]}" -ge "$JOBS" ] && run_batch
    done
    [ "${#batch[@]}" -gt 0 ] && run_batch
    [ "$failed" = 0 ] || exit 1
}

system() {
    echo "== system tests (pytest + pyepics on the real libca)"
    # pyepics is Debian's and imports only under /usr/bin/python3.
    BEAMCTL_BIN="$ROOT/build/release/beamctl" /usr/bin/python3 -m pytest -q -p no:cacheprovider tests/system "$@"
}

case "${1:-}" in
deps) deps test ;;
build) deps; build release ;;
demo)
    # Only the program the demo runs (no unit tests, benchmarks or plugins of the tests).
    deps demo; build release beamctl
    export EPICS_CAS_SERVER_PORT=${EPICS_CAS_SERVER_PORT:-5064}
    echo "== demo beamline IOC: 25 simulated EtherCAT terminals, slit, sample stage, mirror, soft records,"
    echo "   and an RCP machine (beamctl rcp-sim examples/rcp/model.yaml) on the UDP bridge (Ctrl-C to stop)"
    echo "   from another shell, with pyepics:"
    echo "   /usr/bin/python3 -c \"import epics; print(epics.caget('DEMO:m0-Stat-OK', as_string=True), epics.caget('DEMO:RCP:sgDemo:Sine'))\""
    build/release/beamctl rcp-sim examples/rcp/model.yaml &
    sim=$!
    # The CA repeater for the clients (exits at once, quietly, if one already serves the port).
    build/release/beamctl ca-repeater >/dev/null &
    rep=$!
    trap 'kill $sim $rep 2>/dev/null; wait $sim $rep 2>/dev/null' EXIT INT TERM
    build/release/beamctl run examples/demo/ioc.yaml ;;
unit) deps test; build release; unit ;;
system) deps test; build release; shift; system "$@" ;;
fuzz) deps test; fuzz ;;
test)
    deps test
    build release
    # The system tests mostly wait on real time (a 13-minute run takes about 3 minutes of CPU), so
    # they run beside the sanitized build, the unit tests and the fuzzers, which yield the CPU to
    # them (nice 10). Their output follows when both are done; either failing fails the run.
    echo "== system tests start beside the unit tests and the fuzzers (their output follows; log: build/system-tests.log)"
    ( system > build/system-tests.log 2>&1 ) &
    sys_pid=$!
    trap 'kill $sys_pid 2>/dev/null' EXIT
    # (each in a job of its own: `set -e` holds inside it, which a `( ... ) || x` would switch off)
    ( renice -n 10 -p "$BASHPID" >/dev/null; unit; fuzz ) &
    rest_pid=$!
    trap 'kill $sys_pid $rest_pid 2>/dev/null' EXIT
    rest=0
    wait "$rest_pid" || rest=$?
    sys=0
    wait "$sys_pid" || sys=$?
    trap - EXIT
    cat build/system-tests.log
    [ "$rest" = 0 ] || echo "== the unit tests or the fuzzers failed (exit $rest)"
    [ "$sys" = 0 ] || echo "== the system tests failed (exit $sys)"
    [ "$rest" = 0 ] && [ "$sys" = 0 ] ;;
bench) deps test; build release; shift; bash bench/run.sh "$@" ;;
*) echo "usage: bash build.sh {demo|test|deps|build|unit|system|fuzz|bench}"; exit 2 ;;
esac
