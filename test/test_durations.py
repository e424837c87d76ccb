"""The durations file's CPU columns (test/durations.py): a phase's own CPU and its reaped children's, in one
process and through pytest-xdist workers, and each module's totals beside it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

BURN = 0.3
"""CPU seconds each sample test burns (by the process's CPU clock: the same on a loaded machine)."""
SAMPLE = f"""
import subprocess, sys, time

BURN = "import time\\nend = time.process_time() + {BURN}\\nwhile time.process_time() < end: pass"


def test_burns_its_own_cpu():
    end = time.process_time() + {BURN}
    while time.process_time() < end:
        pass


def test_starts_a_child_that_burns():
    subprocess.run([sys.executable, "-c", BURN], check=True)


def test_idle():
    pass
"""


def run_sample(tmp_path: Path, *args: str) -> tuple[str, dict[str, dict[str, float]]]:
    (tmp_path / "test_sample.py").write_text(SAMPLE)
    out = tmp_path / "durations.txt"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "durations", "-p", "no:cacheprovider",
                           f"--durations-file={out}", "--rootdir", str(tmp_path), str(tmp_path / "test_sample.py"),
                           *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    return out.read_text(), json.loads(out.with_suffix(".cpu.json").read_text())


def call_cpu(text: str, name: str) -> tuple[float, float]:
    """(own, children) CPU seconds of test ``name``'s call phase in the durations file."""
    line = next(x for x in text.splitlines() if x.rstrip().endswith(f"::{name}") and " call " in x)
    own, children = line.split("=")[1].split("CPU-s")[0].split("+")
    return float(own), float(children)


@pytest.mark.parametrize("workers", [[], ["-n", "2"]], ids=["one process", "two xdist workers"])
def test_each_phase_has_its_own_and_its_childrens_cpu(tmp_path: Path, workers: list[str]) -> None:
    text, modules = run_sample(tmp_path, *workers)
    own, children = call_cpu(text, "test_burns_its_own_cpu")
    assert own >= BURN - 0.02 and children < 0.05, text
    own, children = call_cpu(text, "test_starts_a_child_that_burns")
    assert children >= BURN - 0.02 and own < BURN / 2, text
    own, children = call_cpu(text, "test_idle")
    assert own + children < 0.05, text
    total = modules["test_sample.py"]
    assert total["own_s"] >= BURN - 0.02 and total["children_s"] >= BURN - 0.02, modules
    assert abs(total["cpu_s"] - total["own_s"] - total["children_s"]) <= 0.1, modules
