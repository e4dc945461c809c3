"""The architecture's layering, checked on the sources (ARCHITECTURE.md section 3): the EtherCAT
master never depends on the simulator, and nothing above the bus reaches into the master (the IOC
talks to ethercat::Bus, the endpoint a scanner client will also stand behind)."""

import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"


def test_the_master_does_not_include_the_simulator():
    bad = []
    for f in sorted((SRC / "ethercat").glob("*.[ch]pp")):
        for n, line in enumerate(f.read_text().splitlines(), 1):
            if re.match(r'\s*#\s*include\s+"ethercat/sim/', line):
                bad.append(f"{f.relative_to(SRC)}:{n}: {line.strip()}")
    assert not bad, "\n".join(bad)


def test_nothing_above_the_bus_reaches_into_the_master():
    bad = []
    for d in ("ioc", "plc", "motion", "pv", "ca", "bridge", "daq"):
        for f in sorted((SRC / d).glob("*.[ch]pp")):
            for n, line in enumerate(f.read_text().splitlines(), 1):
                if re.search(r"(\.|->)master\(\)", line) or "ethercat/master.hpp" in line:
                    bad.append(f"{f.relative_to(SRC)}:{n}: {line.strip()}")
    assert not bad, "\n".join(bad)
