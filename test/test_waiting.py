"""test/waiting.py, the suite's one wait: the value once the condition holds, else a failure that
says what was waited for and what was seen (never a silent return)."""

from __future__ import annotations

import subprocess
import sys
import threading

import pytest
from waiting import exited, wait_for_line, wait_until


def test_wait_until_returns_the_first_truthy_value() -> None:
    calls: list[int] = []

    def third() -> int | None:
        calls.append(1)
        return len(calls) * 10 if len(calls) >= 3 else None

    assert wait_until(third, lambda: calls, what="three calls", interval=0.0) == 30
    steps: list[int] = []
    assert wait_until(lambda: len(steps) >= 2 and "done", lambda: steps, what="two steps",
                      step=lambda: steps.append(1)) == "done"


def test_wait_until_fails_at_the_deadline_with_what_it_saw() -> None:
    with pytest.raises(AssertionError, match=r"for the answer: not within 0.2 s; seen:\n41 so far"):
        wait_until(lambda: None, lambda: "41 so far", what="the answer", timeout=0.2)


def test_a_process_that_exits_ends_the_wait_with_its_code_and_its_lines() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "print('starting'); raise SystemExit(3)"],
                            stdout=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(line.rstrip() for line in proc.stdout or ()))
    reader.start()
    assert wait_for_line(lines, "starting", proc, name="child") == 0  # a line printed before the exit still counts
    with pytest.raises(AssertionError, match=r"'ready' from child: child exited with 3; seen:\nstarting"):
        wait_for_line(lines, "ready", proc, name="child")
    reader.join()
    assert exited(proc)() == "the process exited with 3"
