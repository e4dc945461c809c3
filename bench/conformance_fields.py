#!/usr/bin/python3
"""The fields of every EPICS base record type against beamctl's record types.

    /usr/bin/python3 bench/conformance_fields.py BASE_SRC [--beamctl build/release/beamctl] [--md OUT.md]

BASE_SRC is a checkout (or an archive export) of EPICS base R7.0.8 taken in at development time,
outside this repository; its record definitions are read from
modules/database/src/std/rec/*Record.dbd.pod (with the dbCommon includes), the facts of base's own
`.dbd` files. beamctl's side is `beamctl db --dbd`. For each record type and field:

- served:   beamctl's record type has the field (its DBF type is named when it differs)
- NOACCESS: base's field is DBF_NOACCESS (a pointer or private state); no database may set it,
            and beamctl refuses it by name, as base does
- missing:  base has the field and beamctl does not (a database that sets it is refused, naming it)

Prints a summary per record type; --md writes the table that docs/conformance.md holds between
its `<!-- fields: begin -->` and `<!-- fields: end -->` markers (--update-docs replaces it there).
Nothing here is needed by the build or the tests.
"""
import argparse
import os
import re
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def strip_pod(text):
    out, pod = [], False
    for line in text.splitlines():
        if line.startswith("=cut"):
            pod = False
            continue
        if line.startswith("="):
            pod = True
            continue
        if not pod:
            out.append(line)
    return "\n".join(out)


FIELD = re.compile(r'field\((\w+)\s*,\s*(\w+)\)\s*\{([^}]*)\}')
ATTR = re.compile(r'(\w+)\(("([^"]*)"|[^)]*)\)')


def base_fields(path, dirs):
    text = strip_pod(open(path).read())
    fields = []
    pos = 0
    # fields and includes in file order
    for m in re.finditer(r'include\s+"([^"]+)"|' + FIELD.pattern, text):
        if m.group(1):
            for d in dirs:
                for cand in (os.path.join(d, m.group(1)), os.path.join(d, m.group(1)) + ".pod"):
                    if os.path.exists(cand):
                        fields += base_fields(cand, dirs)
                        break
                else:
                    continue
                break
        else:
            name, dbf, body = m.group(2), m.group(3), m.group(4)
            attrs = {a.group(1): (a.group(3) if a.group(3) is not None else a.group(2)) for a in ATTR.finditer(body)}
            fields.append((name, dbf, attrs))
    return fields


def read_base(src):
    db = os.path.join(src, "modules", "database", "src")
    dirs = [os.path.join(db, "ioc", "db"), os.path.join(db, "std", "rec"), os.path.join(db, "ioc", "bpt")]
    rec_dir = os.path.join(db, "std", "rec")
    types = {}
    for f in sorted(os.listdir(rec_dir)):
        if f.endswith("Record.dbd.pod"):
            types[f[: -len("Record.dbd.pod")]] = base_fields(os.path.join(rec_dir, f), dirs)
    return types


def read_beamctl(binary):
    out = subprocess.run([binary, "db", "--dbd"], capture_output=True, text=True, check=True).stdout
    types, cur = {}, None
    for line in out.splitlines():
        m = re.match(r"recordtype\((\w+)\)", line)
        if m:
            cur = types.setdefault(m.group(1), {})
            continue
        m = re.match(r"\s+field\((\w+),(\w+)\)", line)
        if m and cur is not None:
            cur[m.group(1)] = m.group(2)
    return types


def compare(base, ours):
    rows, summary = [], []
    for t, fields in base.items():
        mine = ours.get(t)
        served = noaccess = missing = 0
        missing_names = []
        for name, dbf, attrs in fields:
            if mine is not None and name in mine:
                served += 1
                status = "served" if mine[name] == dbf or dbf == "DBF_DEVICE" else f"served as {mine[name]}"
            elif dbf == "DBF_NOACCESS":
                noaccess += 1
                status = "NOACCESS"
            else:
                missing += 1
                missing_names.append(name)
                status = "missing"
            rows.append((t, name, dbf, attrs.get("special", ""), status))
        summary.append((t, len(fields), served, noaccess, missing, missing_names, mine is not None))
    return rows, summary


def markdown(summary, base_src):
    total = sum(s[1] for s in summary)
    served = sum(s[2] for s in summary)
    noacc = sum(s[3] for s in summary)
    miss = sum(s[4] for s in summary)
    lines = [
        f"Fields of EPICS base R7.0.8's {len(summary)} record types ({total} fields, dbCommon's included "
        f"in each): **{served} served, {noacc} DBF_NOACCESS (refused by name, as base), {miss} missing**. ",
        "Made by `/usr/bin/python3 bench/conformance_fields.py BASE_SRC --update-docs` from base's "
        "`*Record.dbd.pod` and `beamctl db --dbd`.",
        "",
        "| record type | fields | served | NOACCESS | missing (a database that sets one is refused, naming it) |",
        "|---|---|---|---|---|",
    ]
    for t, n, s, na, m, names, present in summary:
        what = ", ".join(names) if present else "(record type not served)"
        lines.append(f"| {t} | {n} | {s} | {na} | {m}{': ' + what if m else ''} |")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("base_src")
    ap.add_argument("--beamctl", default=os.path.join(ROOT, "build", "release", "beamctl"))
    ap.add_argument("--md")
    ap.add_argument("--update-docs", action="store_true")
    a = ap.parse_args()
    base = read_base(a.base_src)
    ours = read_beamctl(a.beamctl)
    rows, summary = compare(base, ours)
    for t, n, s, na, m, names, present in summary:
        print(f"{t:12s} {n:4d} fields: {s:4d} served, {na:3d} NOACCESS, {m:3d} missing"
              + (f" ({' '.join(names)})" if names else "") + ("" if present else "  [type not served]"))
    md = markdown(summary, a.base_src)
    if a.md:
        open(a.md, "w").write(md)
    if a.update_docs:
        path = os.path.join(ROOT, "docs", "conformance.md")
        text = open(path).read()
        begin, end = "<!-- fields: begin -->", "<!-- fields: end -->"
        if begin not in text:
            sys.exit(f"{path}: no {begin} marker")
        head, rest = text.split(begin, 1)
        _old, tail = rest.split(end, 1)
        open(path, "w").write(head + begin + "\n" + md + end + tail)
    missing = sum(s[4] for s in summary)
    print(f"total: {sum(s[1] for s in summary)} fields, {sum(s[2] for s in summary)} served, "
          f"{sum(s[3] for s in summary)} NOACCESS, {missing} missing")


if __name__ == "__main__":
    main()
