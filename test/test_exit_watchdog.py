"""ros.node_exit.ExitWatchdog: a node whose way out is stuck ends with the stage named and every stack."""

from __future__ import annotations

import threading
import time

import pytest

from dualarm_control.ros.node_exit import EXIT_STUCK_S, ExitWatchdog


def fired(stage: str | None, capsys: pytest.CaptureFixture[str]) -> tuple[list[int], str]:
    codes: list[int] = []
    done = threading.Event()

    def fake_exit(code: int) -> None:
        codes.append(code)
        done.set()

    if stage is None:  # a timer long enough that a loaded machine's delay before cancel() cannot reach it
        watchdog = ExitWatchdog(60.0, exit=fake_exit)
        watchdog.cancel()
        watchdog._timer.join(30.0)  # a cancelled timer's thread ends without calling: nothing may happen
        assert not watchdog._timer.is_alive(), "the cancelled timer's thread is still waiting"
    else:
        ExitWatchdog(0.05, exit=fake_exit, stage=stage)
        assert done.wait(30.0), "the watchdog did not fire within 30 s"
    return codes, capsys.readouterr().err


@pytest.mark.parametrize(("stage", "code"), [("teardown", 0), ("flush", 1), ("close", 1)])
def test_a_stuck_way_out_exits_naming_the_stage_with_every_stack(stage: str, code: int,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    codes, err = fired(stage, capsys)
    assert codes == [code]
    assert f"stuck in '{stage}'" in err
    assert "Thread 0x" in err and "_fire" in err  # every stack, the watchdog thread's too


def test_a_way_out_that_ends_cancels_it(capsys: pytest.CaptureFixture[str]) -> None:
    codes, err = fired(None, capsys)
    assert codes == [] and err == ""


def test_it_fires_before_the_launchers_sigterm() -> None:
    from dualarm_control.app.run.launcher import STOP_GRACE_S
    from dualarm_control.ros.node_exit import ACK_TIMEOUT_S

    assert ACK_TIMEOUT_S < EXIT_STUCK_S < STOP_GRACE_S


def test_the_c_level_dump_is_armed_and_cancelled() -> None:
    """The C-level dump (for a way out stuck holding the GIL) is armed with the watchdog and cancelled
    with it: arming another one then works, and nothing fires after cancel."""
    import faulthandler

    watchdog = ExitWatchdog(60.0, exit=lambda code: None)
    assert watchdog._c_dump
    watchdog.cancel()
    assert not watchdog._c_dump
    faulthandler.cancel_dump_traceback_later()  # idempotent: nothing was left armed


def test_a_timer_that_fires_before_the_constructor_returns_still_exits(monkeypatch: pytest.MonkeyPatch) -> None:
    """The constructor delayed past the timer (as a loaded machine did in a CI run: "the watchdog did not fire
    within 30 s", its thread dead of an AttributeError): the watchdog still exits, once."""
    from dualarm_control.ros import node_exit

    arm = node_exit._dump_stacks_later

    def slow_arm(seconds: float) -> bool:
        armed = arm(seconds)
        time.sleep(0.3)  # the 0.05 s timer would fire here if it were already started
        return armed

    monkeypatch.setattr(node_exit, "_dump_stacks_later", slow_arm)
    codes: list[int] = []
    done = threading.Event()
    ExitWatchdog(0.05, exit=lambda code: (codes.append(code), done.set()), stage="teardown")
    assert done.wait(30.0), "the watchdog did not fire within 30 s"
    assert codes == [0]


def test_a_way_out_stuck_in_a_c_call_holding_the_gil_still_ends() -> None:
    """A process whose way out is stuck in a C call that holds the GIL (the watchdog's thread cannot run; here a
    regular expression backtracking for ever) is ended from C after the watchdog's time: exit 1, every stack on
    stderr (without it, the process would run until killed)."""
    import subprocess
    import sys

    child = ("from dualarm_control.ros.node_exit import ExitWatchdog\n"
             "import re\n"
             "ExitWatchdog(0.2, stage='teardown')\n"
             "re.match(r'(a+)+$', 'a' * 64 + 'b')\n")
    try:
        done = subprocess.run([sys.executable, "-c", child], check=False, capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"the stuck process was still running 30 s later: {exc.stderr!r}")
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    assert "most recent call first" in done.stderr, done.stderr[-2000:]


def test_a_node_process_ends_without_the_interpreters_finalization() -> None:
    """``exit_process``: the code given, what was printed flushed (stdout to a pipe is block-buffered), and no
    finalization (here an atexit handler that would hang for ever, as a middleware destructor did: without it the
    process would not end); every node module's ``__main__`` ends with it (``--help`` through a pipe)."""
    import subprocess
    import sys

    child = ("import atexit, time, sys\n"
             "from dualarm_control.ros.node_exit import exit_process\n"
             "atexit.register(lambda: time.sleep(3600))\n"
             "print('last words', end='')\n"
             "exit_process(3)\n")
    try:
        done = subprocess.run([sys.executable, "-c", child], check=False, capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail("the process ran its finalization (an atexit handler that hangs): still there 30 s later")
    assert (done.returncode, done.stdout) == (3, "last words")
    for module in ("dualarm_control.nodes.controller_node", "dualarm_control.nodes.trajectory_node",
                   "dualarm_sim.sim_node", "dualarm_control.nodes.container"):
        shown = subprocess.run([sys.executable, "-m", module, "--help"], check=False, capture_output=True, text=True,
                               timeout=60)
        assert shown.returncode == 0 and "usage:" in shown.stdout, (module, shown.returncode, shown.stderr[-500:])
