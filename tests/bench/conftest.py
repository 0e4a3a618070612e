"""Print every benchmark's ratio against its goal at the end of the session (with the load)."""

import os

from ._floor import QUICK, RESULTS


def pytest_terminal_summary(terminalreporter):
    if not RESULTS:
        return
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    tr = terminalreporter
    tr.section(f"benchmark ratios ({'quick' if QUICK else 'full'}; load average {load})")
    for name, ratio, goal in RESULTS:
        tr.write_line(f"{name}: {ratio:.3g} (goal <= {goal:g}){'' if ratio <= goal else '  NOT MET'}")
