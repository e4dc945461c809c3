#!/usr/bin/python3
"""The motor record's fields (synApps' motorRecord.dbd, and the ESS/PSI fork's that ecmccfg sets)
against beamctl's `motor` record type.

    /usr/bin/python3 bench/motor_fields.py [--beamctl build/release/beamctl] [--update-docs]

bench/data/motor_fields.json lists the fields as motorRecord.dbd declares them (name, DBF type,
menu, NOACCESS, which source has it, a one-line description in our words), taken in at
development time from a public snapshot of epics-modules/motor (b43050de) and the ESS fork
(c8954721). beamctl's side is `beamctl db --dbd`. Prints the summary; --update-docs writes the
table into docs/conformance.md between `<!-- motor: begin -->` and `<!-- motor: end -->`.
"""
import argparse
import json
import os
import re
import subprocess

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def beamctl_motor_fields(binary):
    out = subprocess.run([binary, "db", "--dbd"], capture_output=True, text=True, check=True).stdout
    fields, inside = {}, False
    for line in out.splitlines():
        if line.startswith("recordtype("):
            inside = line.startswith("recordtype(motor)")
            continue
        m = re.match(r"\s+field\((\w+),(\w+)\)(.*)", line)
        if inside and m:
            fields[m.group(1)] = (m.group(2), "SPC_NOMOD" in m.group(3))
    return fields


# Fields beamctl keeps for databases that set them but that change nothing here (the Soft Channel
# motor device support's links, debugging masks, synApps' internal bookkeeping).
STORED_ONLY = {"CARD", "LRLV", "RVEL", "PP", "MMAP", "NMAP", "ALST", "MLST", "STOO", "DINP", "RINP", "LOCK",
               "SPAM", "MFLG", "MINP", "MISV"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--beamctl", default=os.path.join(ROOT, "build", "release", "beamctl"))
    ap.add_argument("--update-docs", action="store_true")
    a = ap.parse_args()
    spec = json.load(open(os.path.join(HERE, "data", "motor_fields.json")))
    ours = beamctl_motor_fields(a.beamctl)
    rows, served, noacc, missing = [], 0, 0, []
    for f in spec:
        if f["name"] in ours:
            status = "stored only (no effect)" if f["name"] in STORED_ONLY else "served"
            status += " (read-only)" if ours[f["name"]][1] else ""
            served += 1
        elif f["noaccess"]:
            status, noacc = "NOACCESS: refused by name", noacc + 1
        else:
            status = "missing"
            missing.append(f["name"])
        src = "" if f["source"] == "motorRecord.dbd" else " (ESS fork)"
        sets = " ecmccfg sets it." if f["ecmccfg_sets"] else ""
        rows.append(f"| {f['name']}{src} | {f['dbf'].replace('DBF_', '')} | {status} | {f['what']}{sets} |")
    summary = (f"{len(spec)} fields (synApps' motorRecord.dbd and the ESS/PSI fork's that ecmccfg uses): "
               f"**{served} served ({len(STORED_ONLY)} of them stored only), {noacc} DBF_NOACCESS (refused by name), {len(missing)} missing**"
               + (f" ({' '.join(missing)})" if missing else "") + ".")
    print(summary)
    if a.update_docs:
        md = (summary + " Made by `/usr/bin/python3 bench/motor_fields.py --update-docs`.\n\n"
              "| field | DBF | beamctl | what it does |\n|---|---|---|---|\n" + "\n".join(rows) + "\n")
        path = os.path.join(ROOT, "docs", "conformance.md")
        text = open(path).read()
        begin, end = "<!-- motor: begin -->", "<!-- motor: end -->"
        head, rest = text.split(begin, 1)
        _old, tail = rest.split(end, 1)
        open(path, "w").write(head + begin + "\n" + md + end + tail)


if __name__ == "__main__":
    main()
