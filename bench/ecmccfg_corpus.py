#!/usr/bin/python3
"""Runs ecmccfg's own axis YAML and PLC files through beamctl's checkers.

    /usr/bin/python3 bench/ecmccfg_corpus.py ECMCCFG_DIR [--beamctl build/release/beamctl] [--details]

ECMCCFG_DIR is a checkout of paulscherrerinstitute/ecmccfg taken in at development time, outside
this repository (nothing here downloads it; CI does not run this). Every `.plc`/`.plc_inc` and
every axis YAML under examples/ and plc_lib/ is checked the way the example's startup scripts
load it:

- PLC files: `beamctl plc check` with the PLC_MACROS and INC of each `loadPLCFile.cmd` call that
  names the file (each call one check; the file passes when all do), ecmccfg's reserved macros
  (SELF, SELF_ID, M, M_ID) coming from beamctl itself; a PLC that a `loadPLCLib.cmd` call gives
  a function library (the call after its loadPLCFile.cmd) is checked with `beamctl check` of a
  small IOC file whose `plcs:` entry names both. A file no script loads is checked with no
  macros. An include file (`.plc_inc`) passes when a file including it compiles; one that no
  file includes is checked on its own.
- Axis files: `beamctl axis check` with the macros of each `loadYamlAxis.cmd` call (and the
  encoder files of the `loadYamlEnc.cmd` calls after it in the same script); files no script
  loads are checked with no macros. A file with a `plc:` section has its axis PLC compiled.

With --oracle, each axis file is also put through ecmccfg's own loader (scripts/jinja2 of the
checkout: yamllint, the cerberus schema, the jinja2 templates; Debian packages yamllint,
python3-cerberus, python3-jinja2), which says whether ECMC itself accepts it (yamllint's style
rules trailing-spaces and new-line-at-end-of-file are taken as warnings: Debian's yamllint makes
them errors under ecmccfg's relaxed rules, which would refuse most of ecmccfg's own examples;
ecmccfg's other loader, ecb, does not lint): the measure is
"every file ECMC accepts loads in beamctl", and a file ECMC refuses is a real error in the file.

Values a startup script computes at run time (`${ECMC_EC_SLAVE_NUM}`, `$(GRP_x_ID)`) have no
value here: a macro value that refers to one is taken as 1 (a slave or id number in every use
in the corpus), with its `=default` when the reference has one. Prints one line per file and a
summary; --details adds the first error of each failure.
"""
import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile

ENV_REF = re.compile(r"\$[({]([A-Za-z0-9_]+)(?:=([^)}]*))?[)}]")
CALL = re.compile(r"(loadPLCFile|loadPLCLib|loadYamlAxis|loadYamlEnc)\.cmd\s*,?\s*\(?\s*\"([^\"]*)\"")


def resolve_env(value, root, env=None, unknown="1"):
    """Replaces the startup script's run-time values (see the module doc): its epicsEnvSet
    values so far, else the reference's default, else `unknown`."""
    env = env or {}

    def sub(m):
        name, default = m.group(1), m.group(2)
        if name == "ecmccfg_DIR":
            return root + "/"
        if name == "ecmc_master_slave_DIR":
            return root + "/plc_lib/master_slave/"
        if name in env:
            return env[name]
        if default is not None:
            return default
        return unknown
    for _ in range(3):
        value = ENV_REF.sub(sub, value)
    return value


def split_args(text):
    """'A=1, B='x=1, y=2', C' -> {'A': '1', 'B': 'x=1, y=2'} (iocsh macro-argument style)."""
    out, i, n = {}, 0, len(text)
    while i < n:
        while i < n and text[i] in " ,\t":
            i += 1
        j = i
        while j < n and text[j] not in "=,":
            j += 1
        key = text[i:j].strip()
        if j >= n or text[j] == ",":
            i = j + 1
            continue
        j += 1
        while j < n and text[j] == " ":
            j += 1
        if j < n and text[j] in "'\"":
            q = text[j]
            k = text.find(q, j + 1)
            k = n if k < 0 else k
            val = text[j + 1:k]
            i = k + 1
        else:
            k = j
            while k < n and text[k] != ",":
                k += 1
            val = text[j:k].strip()
            i = k
        if key:
            out[key] = val
    return out


def scripts(root):
    """Startup scripts: any text file that is not a PLC, YAML or database file (the examples
    name theirs startup.cmd, st.cmd, startup.script_ecmc_local_hw, ...)."""
    for d, _, files in os.walk(root):
        if "/.git" in d or "scripts/jinja2" in d:
            continue
        for f in files:
            if not f.endswith((".plc", ".plc_inc", ".yaml", ".yml", ".db", ".template", ".md", ".py", ".ui", ".bob", ".png", ".pdf")):
                yield os.path.join(d, f)


ENV_SET = re.compile(r"epicsEnvSet\s*\(?\s*\"?([A-Za-z0-9_]+)\"?\s*,?\s*\"([^\"]*)\"")


def collect_calls(root):
    """{abs file: [(macros, include dirs, libraries or encoder files)]} from every startup script
    (a PLC's libraries: [(file, PLC_MACROS)] of the loadPLCLib.cmd calls after it)."""
    plc_calls, axis_calls = collections.defaultdict(list), collections.defaultdict(list)
    for script in scripts(root):
        d = os.path.dirname(script)
        last_axis = last_plc = None
        env = {}  # epicsEnvSet values so far: the axis file's ${NAME} sees them (iocsh expands it)
        try:
            lines = open(script, errors="replace").read().splitlines()
        except OSError:
            continue
        for line in lines:
            if line.lstrip().startswith("#"):
                continue
            e = ENV_SET.search(line)
            if e:
                env[e.group(1)] = resolve_env(e.group(2), root, env)
            m = CALL.search(line)
            if not m:
                continue
            args = split_args(m.group(2))
            path = resolve_env(args.get("FILE", ""), root)
            if not path:
                continue
            path = os.path.normpath(os.path.join(d, path))
            macros = dict(env)
            macros.update({k: resolve_env(v, root) for k, v in args.items()
                      if k not in ("FILE", "PLC_ID", "SAMPLE_RATE_MS", "INC", "DESC", "PLC_MACROS")})
            if m.group(1) == "loadPLCFile":
                pm = args.get("PLC_MACROS", "")
                whole = ENV_REF.fullmatch(pm.strip())  # PLC_MACROS='${PLC_MACROS}': the script's set
                pm = resolve_env(pm, root, env, unknown="" if whole else "1")
                inc = [os.path.normpath(os.path.join(d, p))
                       for p in resolve_env(args.get("INC", "."), root).split(":") if p]
                last_plc = (pm, inc, [])
                plc_calls[path].append(last_plc)
            elif m.group(1) == "loadPLCLib":
                if last_plc is not None:
                    last_plc[2].append((path, resolve_env(args.get("PLC_MACROS", ""), root, env)))
            elif m.group(1) == "loadYamlAxis":
                last_axis = (macros, [d], [])  # [d]: the IOC's directory (ECMC's working directory)
                axis_calls[path].append(last_axis)
            elif last_axis is not None:  # loadYamlEnc: belongs to the axis before it
                last_axis[2].append(path)
    return plc_calls, axis_calls


UNDEFINED = re.compile(r"undefined macro '([A-Za-z0-9_]+)'")


def run(cmd, macros="", cwd=None):
    """Runs a check (in `cwd`: the IOC's directory, against which ECMC resolves relative file
    names); a macro the traced startup scripts leave undefined (set by an included script or
    computed at run time) is taken as 1, as the run-time values above."""
    extra = []
    for _ in range(12):
        m = ",".join(x for x in [macros] + [f"{k}=1" for k in extra] if x.strip())
        p = subprocess.run(cmd[:3] + (["-m", m] if m else []) + cmd[3:], capture_output=True, text=True, cwd=cwd)
        msg = (p.stderr or p.stdout).strip()
        u = UNDEFINED.search(msg)
        if p.returncode == 0 or not u or u.group(1) in extra:
            return p.returncode == 0, msg
        extra.append(u.group(1))
    return False, msg


ORACLE = """
import sys
sys.path.insert(0, '.')
import ecmcYamlLinter
for rule in ("trailing-spaces", "new-line-at-end-of-file", "new-lines"):  # style only (see above)
    ecmcYamlLinter.relaxedRule["rules"][rule] = {"level": "warning"}
import ecmcAxes
a = ecmcAxes.EcmcAxis(sys.argv[1], './templates/')
a.create()
a.make()
"""


def ecmc_accepts(root, f):
    """(accepted, last line of its complaint) from ecmccfg's own axis loader."""
    p = subprocess.run(["/usr/bin/python3", "-c", ORACLE, f], cwd=os.path.join(root, "scripts", "jinja2"),
                       capture_output=True, text=True)
    why = re.sub(r"\x1b\[[0-9;]*m", "", p.stderr + p.stdout).strip().splitlines()
    why = [w for w in why if w.strip() and "warning" not in w]
    return p.returncode == 0, " ".join(w.strip() for w in why[-3:])[:200]


def macro_arg(m):
    if isinstance(m, dict):
        return ",".join(f"{k}={v}" for k, v in m.items())
    return m


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root")
    ap.add_argument("--beamctl", default=os.path.join(os.path.dirname(__file__), "..", "build", "release", "beamctl"))
    ap.add_argument("--details", action="store_true")
    ap.add_argument("--oracle", action="store_true", help="ask ecmccfg's own loader about each axis file")
    ap.add_argument("--strict", action="store_true",
                    help="check PLC files with `plc check --strict` (ECMC's own files should pass it)")
    a = ap.parse_args()
    root = os.path.abspath(a.root)
    plc_calls, axis_calls = collect_calls(root)
    corpus = sorted(os.path.join(d, f) for top in ("examples", "plc_lib")
                    for d, _, fs in os.walk(os.path.join(root, top)) for f in fs)
    plcs = [f for f in corpus if f.endswith(".plc")]
    incs = [f for f in corpus if f.endswith(".plc_inc")]
    axes = [f for f in corpus if f.endswith((".yaml", ".yml")) and re.search(r"^\s*(axis|encoder)\s*:",
            open(f, errors="replace").read(), re.M) and re.search(r"^\s*axis\s*:", open(f, errors="replace").read(), re.M)]
    results = {}
    std_inc = [os.path.join(root, "plc_lib"), os.path.join(root, "plc_lib", "master_slave")]

    def check_with_libraries(f, pm, inc, libs):
        """`beamctl check` of an IOC file with one PLC: `f` with its libraries and macros."""
        macros = dict(kv.split("=", 1) for kv in (pm + "," + ",".join(m for _, m in libs)).split(",") if "=" in kv)
        with tempfile.TemporaryDirectory() as d:
            yaml = os.path.join(d, "ioc.yaml")
            with open(yaml, "w") as out:
                out.write("ioc: {name: CORPUS}\nengine: {rate_hz: 1000}\nplcs:\n")
                out.write(f"  - id: 0\n    file: {json.dumps(f)}\n    strict: {'true' if a.strict else 'false'}\n")
                out.write(f"    libraries: {json.dumps([lib for lib, _ in libs])}\n")
                out.write(f"    include: {json.dumps(inc + std_inc)}\n")
                out.write(f"    macros: {json.dumps({k.strip(): v.strip() for k, v in macros.items()})}\n")
            p = subprocess.run([a.beamctl, "check", yaml], capture_output=True, text=True)
            return p.returncode == 0, (p.stderr or p.stdout).strip()

    def check_plc(f):
        calls = plc_calls.get(f) or [("", [os.path.dirname(f)], [])]
        errs = []
        for pm, inc, libs in calls:
            if libs:
                ok, msg = check_with_libraries(f, pm, inc, libs)
            else:
                cmd = [a.beamctl, "plc", "check"] + (["--strict"] if a.strict else [])
                for d in inc + std_inc:
                    cmd += ["-I", d]
                ok, msg = run(cmd + [f], pm)
            if not ok:
                errs.append(msg)
        return not errs, errs[0] if errs else ""

    for f in plcs:
        results[f] = check_plc(f)
    includers = collections.defaultdict(list)
    for f in plcs + incs:
        for name in re.findall(r"^\s*include\s+\"([^\"]+)\"", open(f, errors="replace").read(), re.M):
            for g in incs:
                if os.path.basename(g) == os.path.basename(name):
                    includers[g].append(f)
    for f in incs:
        results[f] = None
    for _ in range(3):  # includes of includes
        for f in incs:
            users = [u for u in includers[f] if results.get(u) is not None]
            if users:
                oks = [u for u in users if results[u][0]]
                results[f] = (True, "") if oks else (False, f"no file including it compiles ({os.path.relpath(users[0], root)}: {results[users[0]][1]})")
    for f in incs:
        if results[f] is None:
            results[f] = check_plc(f)
    for f in axes:
        calls = axis_calls.get(f) or [({}, [], [])]
        errs = []
        for macros, dirs, encs in calls:
            cmd = [os.path.abspath(a.beamctl), "axis", "check"]
            for e in encs:
                cmd += ["-e", e]
            ok, msg = run(cmd + [f], macro_arg(macros), dirs[0] if dirs else None)
            if not ok:
                errs.append(msg)
        results[f] = (not errs, errs[0] if errs else "")
    oracle = {f: ecmc_accepts(root, f) for f in axes} if a.oracle else {}

    def table(files, title):
        ok = sum(1 for f in files if results[f][0])
        print(f"== {title}: {ok} of {len(files)} load and compile")
        for f in files:
            good, msg = results[f]
            tag = ""
            if f in oracle:
                tag = " (ECMC accepts it)" if oracle[f][0] else " (ECMC refuses it: " + oracle[f][1] + ")"
            print(f"{'ok  ' if good else 'FAIL'} {os.path.relpath(f, root)}{tag}")
            if not good and a.details:
                print("     " + msg.splitlines()[0][:300])
        return ok
    n = table(plcs, "PLC files (.plc)") + table(incs, "PLC include files (.plc_inc)") + table(axes, "axis files")
    total = len(plcs) + len(incs) + len(axes)
    print(f"== total: {n} of {total}")
    if oracle:
        acc = [f for f in axes if oracle[f][0]]
        print(f"== axis files ECMC accepts: {sum(1 for f in acc if results[f][0])} of {len(acc)} load in beamctl; "
              f"ECMC refuses {len(axes) - len(acc)} (beamctl refuses {sum(1 for f in axes if not oracle[f][0] and not results[f][0])} of them)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
