#!/usr/bin/env bash
# Loads every database file of ecmccfg's db/ folder (.template, .db) with `beamctl db`, offline, and
# counts how many load; prints the first error of each that does not.
#   bash bench/ecmccfg_db.sh ECMCCFG_DIR [BEAMCTL]
# ECMCCFG_DIR is a checkout of paulscherrerinstitute/ecmccfg taken in at development time, outside
# this repository (nothing here downloads it; CI does not run this). Every macro a file references
# is given the value 1 (a slave, axis or channel number in most uses), as a startup script would
# give it some value: record names that need two different macros to differ then collide, which
# is counted as a failure like any other.
set -u
dir=${1:?ECMCCFG_DIR}
beamctl=${2:-$(dirname "$0")/../build/release/beamctl}
ok=0
bad=0
while IFS= read -r f; do
    macros=$(grep -o '\$[({][A-Za-z0-9_]*' "$f" | sed 's/^\$[({]//' | sort -u | awk '{printf "%s%s=1", (NR > 1 ? "," : ""), $1}')
    if out=$("$beamctl" db ${macros:+-m "$macros"} "$f" 2>&1 >/dev/null); then
        ok=$((ok + 1))
    else
        bad=$((bad + 1))
        echo "${out%%$'\n'*}"
    fi
done < <(find "$dir/db" \( -name '*.template' -o -name '*.db' \) | sort)
echo "ecmccfg db/: $ok of $((ok + bad)) files load, $bad do not"
