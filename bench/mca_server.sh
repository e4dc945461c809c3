#!/usr/bin/env bash
# A 16-element MCA in a running IOC (issue 16): 16 elements x 4096 channels and their sum, every
# spectrum read at 10 Hz (the mca.db Read records' SCAN set to .1 second) while acquiring, a
# pyepics client monitoring the 17 spectra. Reports the server's CPU over SECS seconds idle and
# acquiring, and the spectra/s the client received.
#   bash bench/mca_server.sh [SECS=10]
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${1:-10}
BEAMCTL=${BEAMCTL_BIN:-$PWD/build/release/beamctl}
work=$(mktemp -d)
trap 'kill $ioc 2>/dev/null || true; rm -rf "$work"' EXIT
cat > "$work/ioc.yaml" <<'YAML'
ioc: {name: MB}
detectors:
  mca:
    - name: mca1
      elements: 16
      channels: 4096
      slope: 0.005
      background: 500
      lines:
        - {name: Fe Ka, energy: 6.404, rate: 8000, fwhm: 0.16}
        - {name: Cu Ka, energy: 8.048, rate: 5000, fwhm: 0.18}
        - {name: Zn Ka, energy: 8.639, rate: 3000, fwhm: 0.18}
YAML
. bench/ioc_under_test.sh
start_ioc "$work/ioc.yaml" "$work/ioc.log"
EPICS_CA_MAX_ARRAY_BYTES=1000000 \
/usr/bin/python3 - "$SECS" "$ioc" <<'PY'
import sys, time, epics
secs, pid = float(sys.argv[1]), int(sys.argv[2])
def cpu():  # the server's user + system time [s]
    f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / 100
P = "MB:"
names = [f"mca{i}" for i in range(1, 17)] + ["mcaSum"]
for n in names:
    epics.caput(P + n + "Read.SCAN", ".1 second", wait=True)
got = []
pvs = [epics.PV(P + n, auto_monitor=True, callback=lambda value=None, **kw: got.append(len(value) if hasattr(value, "__len__") else 1)) for n in names]
for pv in pvs:
    pv.wait_for_connection(5)
time.sleep(1)
c0, t0 = cpu(), time.time()
time.sleep(secs)
c1, t1 = cpu(), time.time()
idle = 100 * (c1 - c0) / (t1 - t0)
epics.caput(P + "PresetMode", "No preset", wait=True)
epics.caput(P + "EraseStart", 1)
time.sleep(1.5)
got.clear()
c0, t0 = cpu(), time.time()
time.sleep(secs)
c1, t1 = cpu(), time.time()
epics.caput(P + "StopAll", 1, wait=True)
busy = 100 * (c1 - c0) / (t1 - t0)
print(f"16 elements x 4096 channels + the sum, read at 10 Hz, one pyepics monitor on the 17 spectra: "
      f"server CPU idle {idle:.1f} %, acquiring {busy:.1f} % of a core; "
      f"client received {len(got) / (t1 - t0):.1f} spectra/s ({sum(got) * 4 / (t1 - t0) / 1e6:.2f} MB/s)")
PY
