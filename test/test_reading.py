"""test/reading.py: a child's next line within a deadline, failing with what was seen."""

from __future__ import annotations

import subprocess
import sys

import pytest
from reading import read_line


def child(code: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_lines_are_read_one_by_one_and_nothing_is_read_ahead() -> None:
    proc = child("print('ready', flush=True); print('second'); print('rest')")
    try:
        assert read_line(proc, what="ready", timeout=60) == "ready"
        assert read_line(proc, what="second", timeout=60) == "second"
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert out == "rest\n"


def test_a_child_that_never_prints_fails_on_the_deadline() -> None:
    proc = child("import time; print('rea', end='', flush=True); time.sleep(60)")
    try:
        with pytest.raises(AssertionError, match=r"waited .* for the line: not within 1 s; seen:\nstdout so far b'rea'; "
                                                 r"exit code None"):
            read_line(proc, what="the line", timeout=1)
    finally:
        proc.kill()
        proc.wait(timeout=60)


def test_a_child_that_exits_fails_with_its_stderr() -> None:
    proc = child("import sys; print('no', end='', flush=True); sys.exit('boom: no service')")
    try:
        with pytest.raises(AssertionError, match=r"its stdout closed; seen:\nstdout so far b'no'; exit code 1; "
                                                 r"stderr:\nboom: no service"):
            read_line(proc, what="the line", timeout=60)
    finally:
        proc.kill()
        proc.wait(timeout=60)
