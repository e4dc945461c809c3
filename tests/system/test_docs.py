"""The docs' worked examples, run: every ```sh block of README.md and docs/*.md that a
`<!-- test -->` line precedes runs with bash from the repository root, and what it prints is
compared with what the block says it prints, so that no figure in the docs can go stale.

The convention (docs/README.md, "Worked examples are tested", says it for writers):

- `# -> TEXT` at the end of a line (a shell command, or a python `print` in a heredoc): that line
  prints the line TEXT. `...` in TEXT stands for any text. `# ~> TEXT`: the same, but every
  number within ±20 % of the one shown (values that depend on timing).
- What the block prints on standard output must be exactly its `# ->` lines, in order: a line
  that prints something nobody wrote down fails the test as much as a wrong figure.
- A line ending in `&` runs in the background: its output goes apart (its own `# ->` lines must
  appear in it, in order), and the block goes on once it printed its `ready:` line.
- `build/release/beamctl` is the binary under test (BEAMCTL_BIN; `beamctl` is on PATH too). The
  Channel Access port is a free one (EPICS_CAS_SERVER_PORT and EPICS_CA_SERVER_PORT), so the
  docs say 127.0.0.1 and mean the default port; in the output that port reads 5064.
- The block runs under `set -e`, with a time-out; every process it started is stopped at the end.
- `<!-- test: skip: REASON -->` marks a block that cannot run here (privileges, hardware, a
  build); every ```sh block carries one of the two markers.
"""

import os
import re
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from conftest import BEAMCTL, REPEATER_PORT, REPO_ROOT, acquire_port, release_port, require_binary

DOC_FILES = [REPO_ROOT / "README.md"] + sorted((REPO_ROOT / "docs").glob("*.md"))
BLOCK_TIMEOUT = 300.0  # [s] against a hung block only; a normal one takes seconds
DOC_PORT = 5064        # the port the docs assume; the test's free port is shown as this
TOLERANCE = 0.20       # `~>`: relative tolerance of every number

MARKER = re.compile(r"^<!--\s*test(?::\s*(?P<arg>.*?))?\s*-->\s*$")
FENCE = re.compile(r"^(?P<fence>`{3,})(?P<lang>[^`\s]*)\s*$")
EXPECT = re.compile(r"(?:^|\s)#\s(?P<kind>->|~>)\s(?P<text>.*?)\s*$")
BACKGROUND = re.compile(r"^(?P<cmd>.*[^&\s])\s*&(?P<rest>\s*(?:#.*)?)$")
HEREDOC = re.compile(r"<<-?\s*(['\"]?)(?P<word>\w+)\1")
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Expect:
    line: int          # line in the .md file
    kind: str          # "->" or "~>"
    text: str

    def matches(self, actual):
        if self.kind == "->":
            parts = [re.escape(p) for p in self.text.split("...")]
            return re.fullmatch(".*".join(parts), actual) is not None
        want_nums, got_nums = NUMBER.findall(self.text), NUMBER.findall(actual)
        if NUMBER.sub("#", self.text) != NUMBER.sub("#", actual) or len(want_nums) != len(got_nums):
            return False
        return all(abs(float(g) - float(w)) <= TOLERANCE * abs(float(w)) for w, g in zip(want_nums, got_nums))


@dataclass
class Block:
    path: Path
    line: int          # line of the opening fence
    lang: str
    marker: str | None  # None: no marker; "" : `<!-- test -->`; else the text after `test:`
    lines: list = field(default_factory=list)  # (line number, text)

    @property
    def name(self):
        return f"{self.path.relative_to(REPO_ROOT)}:{self.line}"


def read_blocks(path):
    """The fenced code blocks of a markdown file, each with the marker of the line before it."""
    blocks, current, fence, prev = [], None, "", ""
    for n, text in enumerate(path.read_text().splitlines(), start=1):
        if current is not None:
            # a fence closes with at least as many backticks as opened it (```` around ``` examples)
            if text.strip().startswith(fence) and set(text.strip()) == {"`"}:
                blocks.append(current)
                current = None
            else:
                current.lines.append((n, text))
        elif (m := FENCE.match(text)):
            mark = MARKER.match(prev)
            fence = m["fence"]
            current = Block(path, n, m["lang"], (mark["arg"] or "") if mark else None)
        prev = text
    return blocks


def shell_blocks():
    return [b for f in DOC_FILES for b in read_blocks(f) if b.lang in ("sh", "bash")]


PROLOGUE = r"""
set -e
__doc_ready() {  # N PID: wait until background job N has printed its 'ready:' line
    until grep -q '^ready:' "$DOCTEST_BG/$1.out" 2>/dev/null; do
        if ! kill -0 "$2" 2>/dev/null && ! grep -q '^ready:' "$DOCTEST_BG/$1.out" 2>/dev/null; then
            echo "doc test: background job $1 ended before it printed 'ready:'; its stderr:" >&2
            tail -n 20 "$DOCTEST_BG/$1.err" >&2
            exit 1
        fi
        sleep 0.05
    done
}
"""


def script_of(block):
    """The bash script that runs `block`, with the expectations of its foreground output and of
    each background job's."""
    out, fg, bg = [PROLOGUE], [], []
    heredoc_end = None
    for n, text in block.lines:
        m = EXPECT.search(text)
        expect = Expect(n, m["kind"], m["text"]) if m else None
        if heredoc_end is not None:  # inside a heredoc: python prints
            if text.strip() == heredoc_end:
                heredoc_end = None
            elif expect:
                fg.append(expect)
            out.append(text)
            continue
        if (h := HEREDOC.search(text)):
            heredoc_end = h["word"]
        code = text.replace("build/release/beamctl", str(BEAMCTL))
        if heredoc_end is None and (b := BACKGROUND.match(code)):
            k = len(bg) + 1
            bg.append([expect] if expect else [])
            out.append(f'{b["cmd"]} >"$DOCTEST_BG/{k}.out" 2>"$DOCTEST_BG/{k}.err" &{b["rest"]}')
            out.append(f"__doc_ready {k} $!")
            continue
        if expect:
            fg.append(expect)
        out.append(code)
    return "\n".join(out) + "\n", fg, bg


def normalise(text, port):
    return [line.rstrip().replace(f":{port}", f":{DOC_PORT}") for line in text.splitlines()]


def stop_group(pgid):
    """SIGTERM to every process of the block's group, SIGKILL to what is left after 10 s."""
    for sig, grace in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            return
        end = time.monotonic() + grace
        while time.monotonic() < end:
            try:
                os.killpg(pgid, 0)
            except ProcessLookupError:
                return
            time.sleep(0.05)


def run_block(block, workdir):
    """Runs the block; returns a list of problems (empty: it printed what the docs say)."""
    script, fg, bg = script_of(block)
    bgdir = Path(workdir) / "bg"
    bgdir.mkdir(parents=True, exist_ok=True)
    bindir = Path(workdir) / "bin"
    bindir.mkdir(exist_ok=True)
    if not (bindir / "beamctl").exists():
        (bindir / "beamctl").symlink_to(BEAMCTL)
    port = acquire_port()
    env = dict(os.environ)
    env.update({
        "PATH": f"{bindir}:{env.get('PATH', '/usr/bin:/bin')}",
        "EPICS_CAS_SERVER_PORT": str(port),
        "EPICS_CA_SERVER_PORT": str(port),
        "EPICS_CA_ADDR_LIST": "127.0.0.1",
        "EPICS_CA_AUTO_ADDR_LIST": "NO",
        "EPICS_CAS_BEACON_ADDR_LIST": f"127.0.0.1:{REPEATER_PORT}",
        "EPICS_CAS_AUTO_BEACON_ADDR_LIST": "NO",
        "DOCTEST_BG": str(bgdir),
    })
    proc = subprocess.Popen(["bash", "-c", script], cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
                            start_new_session=True)
    try:
        try:
            stdout, stderr = proc.communicate(timeout=BLOCK_TIMEOUT)
        except subprocess.TimeoutExpired:
            stop_group(proc.pid)
            stdout, stderr = proc.communicate()
            return [f"{block.name}: did not finish within {BLOCK_TIMEOUT:.0f} s\n"
                    f"stdout:\n{stdout}\nstderr:\n{stderr[-3000:]}"]
    finally:
        stop_group(proc.pid)
        release_port(port)

    problems = []
    rel = block.path.relative_to(REPO_ROOT)
    got = normalise(stdout, port)
    if proc.returncode != 0:
        problems.append(f"{block.name}: exit code {proc.returncode}")
    for i in range(max(len(fg), len(got))):
        if i >= len(fg):
            problems.append(f"{block.name}: prints a line the docs do not show: {got[i]!r}")
        elif i >= len(got):
            problems.append(f"{rel}:{fg[i].line}: expected {fg[i].text!r}, got nothing")
        elif not fg[i].matches(got[i]):
            problems.append(f"{rel}:{fg[i].line}: expected {fg[i].text!r}, got {got[i]!r}")
    for k, expects in enumerate(bg, start=1):
        out_path = bgdir / f"{k}.out"
        lines = normalise(out_path.read_text(errors="replace"), port) if out_path.exists() else []
        rest = iter(lines)
        for e in expects:
            if not any(e.matches(line) for line in rest):
                problems.append(f"{rel}:{e.line}: expected {e.text!r} in the background job's output, "
                                f"which was {lines!r}")
    if problems:
        problems.append(f"stdout:\n{stdout}\nstderr:\n{stderr[-3000:]}")
    return problems


BLOCKS = shell_blocks()
TESTED = [b for b in BLOCKS if b.marker == ""]
SKIPPED = [b for b in BLOCKS if b.marker and b.marker.startswith("skip:")]


@pytest.mark.parametrize("block", TESTED, ids=[b.name for b in TESTED])
def test_worked_example(block, tmp_path):
    require_binary()
    problems = run_block(block, tmp_path)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("block", SKIPPED, ids=[b.name for b in SKIPPED])
def test_worked_example_not_run_here(block):
    pytest.skip(f"{block.name}: {block.marker[len('skip:'):].strip()}")


def test_every_shell_block_is_marked():
    """A block nobody marks is a block nobody runs: each ```sh block says whether it is tested."""
    unmarked = [b.name for b in BLOCKS if b.marker is None]
    bad = [f"{b.name}: <!-- test: {b.marker} -->" for b in BLOCKS
           if b.marker not in (None, "") and not (b.marker.startswith("skip:") and b.marker[5:].strip())]
    assert not unmarked, ("```sh blocks without <!-- test --> or <!-- test: skip: REASON --> on the line "
                          "before: " + ", ".join(unmarked))
    assert not bad, "markers other than <!-- test --> and <!-- test: skip: REASON -->: " + ", ".join(bad)
    assert TESTED, "no tested block found: the marker convention changed?"


def test_a_wrong_figure_fails(tmp_path):
    """The runner itself: a block whose output differs from its `# ->` lines, or prints an
    unmarked line, or whose background job never gets ready, is reported with the doc line."""
    doc = tmp_path / "doc.md"
    doc.write_text("\n".join([
        "<!-- test -->",
        "```sh",
        "echo 'OK (885 PVs, 1 bus(es))'   # -> OK (147 PVs, 1 bus(es))",
        "echo 19000                       # ~> 19660",
        "echo 30000                       # ~> 19660",
        "echo extra",
        "```",
        "<!-- test -->",
        "```sh",
        "sleep 0.2 &",
        "```",
    ]) + "\n")
    wrong, not_ready = read_blocks(doc)
    for b in (wrong, not_ready):
        b.path = REPO_ROOT / "docs" / "x.md"  # a name relative to the repository
    problems = "\n".join(run_block(wrong, tmp_path / "a"))
    assert "docs/x.md:3: expected 'OK (147 PVs, 1 bus(es))', got 'OK (885 PVs, 1 bus(es))'" in problems
    assert "docs/x.md:4" not in problems  # 19000 is within 20 % of 19660
    assert "docs/x.md:5: expected '19660', got '30000'" in problems
    assert "prints a line the docs do not show: 'extra'" in problems
    problems = "\n".join(run_block(not_ready, tmp_path / "b"))
    assert "background job 1 ended before it printed 'ready:'" in problems
    assert "exit code 1" in problems
