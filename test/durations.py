"""Every test phase's duration and CPU time, written to a file when the session ends (``--durations-file``;
``make test`` writes out/test-durations*.txt and CI prints them; docs/testing.md).

The suite is CPU-bound on two cores, so what a test costs the run is its CPU time more than its wall time:
each process that runs tests (every xdist worker, the background and realtime runs) measures each phase's
CPU seconds, its own (``RUSAGE_SELF``) and those of the child processes it reaped during the phase
(``RUSAGE_CHILDREN``: the nodes, launches, recorders and tools the test started, with their own reaped
children). A process a module keeps running (a shared launch) counts in the phase that reaps it, usually the
module's last teardown, so the module totals are right where single phases are not; a process nobody reaps
(none should be left: ``conftest.no_process_outlives_its_module``) is not counted.
"""

from __future__ import annotations

import json
import resource
from collections.abc import Generator
from pathlib import Path
from typing import Any, cast

import pytest

CPU_KEY = "cpu_s"
"""The report's user property holding (own, children) CPU seconds of the phase."""


def cpu_seconds() -> tuple[float, float]:
    """(this process's, its reaped children's) user + system CPU seconds so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


class PhaseCpu:
    """Measures each phase's CPU in the process that runs it and puts it on the phase's report (a user
    property: xdist sends it to the controller with the report)."""

    def __init__(self) -> None:
        self._start = cpu_seconds()

    def pytest_runtest_logstart(self) -> None:
        """The item's first phase starts here (the phases follow each other: each starts where the last ended)."""
        self._start = cpu_seconds()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self) -> Generator[None, Any, None]:
        end = cpu_seconds()
        outcome = yield
        start, self._start = self._start, end
        outcome.get_result().user_properties.append((CPU_KEY, (end[0] - start[0], end[1] - start[1])))


def phase_cpu(report: pytest.TestReport) -> tuple[float, float]:
    """The (own, children) CPU seconds :class:`PhaseCpu` put on ``report``; (0, 0) where none."""
    for key, value in report.user_properties:
        if key == CPU_KEY:
            pair = cast(tuple[float, float], value)
            return float(pair[0]), float(pair[1])
    return 0.0, 0.0


class DurationsFile:
    """Every test phase's duration [s] and CPU [s], slowest first, written to ``path`` when the session ends (in
    the process that reports: the xdist controller gets its workers' reports); each module's seconds to
    ``.modules.json`` beside it and each module's CPU seconds (own + children) to ``.cpu.json``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows: list[tuple[float, float, float, str, str]] = []

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        own, children = phase_cpu(report)
        self.rows.append((report.duration, own, children, report.when, report.nodeid))

    def pytest_sessionfinish(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        total = sum(r[0] for r in self.rows)
        cpu = sum(r[1] + r[2] for r in self.rows)
        self.path.write_text(
            f"# {len(self.rows)} test phases, {total:.1f} s in all (summed over workers), {cpu:.1f} CPU-s "
            "(the test processes' own + the children they reaped; columns: wall, CPU own + children)\n"
            + "".join(f"{d:8.2f}s {own + children:8.2f} = {own:.2f} + {children:.2f} CPU-s {when:<8} {nodeid}\n"
                      for d, own, children, when, nodeid in sorted(self.rows, reverse=True)))
        seconds: dict[str, float] = {}
        cpu_modules: dict[str, list[float]] = {}
        for d, own, children, _, nodeid in self.rows:
            name = Path(nodeid.split("::")[0]).name
            seconds[name] = seconds.get(name, 0.0) + d
            parts = cpu_modules.setdefault(name, [0.0, 0.0])
            parts[0] += own
            parts[1] += children
        self.path.with_suffix(".modules.json").write_text(json.dumps(
            {k: round(v, 1) for k, v in sorted(seconds.items(), key=lambda kv: -kv[1])}, indent=1) + "\n")
        self.path.with_suffix(".cpu.json").write_text(json.dumps(
            {k: {"cpu_s": round(o + c, 1), "own_s": round(o, 1), "children_s": round(c, 1)}
             for k, (o, c) in sorted(cpu_modules.items(), key=lambda kv: -sum(kv[1]))}, indent=1) + "\n")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--durations-file", default="", help="write every test phase's duration and CPU time to this "
                     "file, slowest first, and each module's beside it (make test writes out/test-durations*.txt and "
                     "CI prints them; test/durations.py)")


def pytest_configure(config: pytest.Config) -> None:
    """The CPU measure in every test process, the file in the reporting one, when ``--durations-file`` is set."""
    path = config.getoption("--durations-file")
    if not path:
        return
    config.pluginmanager.register(PhaseCpu(), "phase-cpu")
    if not hasattr(config, "workerinput"):
        config.pluginmanager.register(DurationsFile(Path(path)), "durations-file")
