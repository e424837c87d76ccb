"""Independent launches of one test fixture side by side, each on a ROS domain of its own.

A lockstep launch spends much of its time waiting, not computing: its nodes hand each cycle
from one process to the next, and at the end each node waits for its readers to acknowledge
what it published (``ros.node_exit.flush_publishers``, seconds with Fast DDS's default heartbeat).
Four launches of the short scenario side by side took 16-17 s on the 2-core machine, one after
the other 29 s. Lockstep runs do not depend on timing (the same commands and states however the
processes are scheduled), so what the tests assert is the same either way.

Each launch runs on a ROS domain leased for it (:mod:`domains`: no other live test, in this
process or another, holds it), so that the graphs do not see each other. The same goes for a
launch in the background while in-process tests go on (:func:`in_background`), and for a
computation in this process while launches run (:func:`meanwhile`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from typing import TypeVar

import pytest
from domains import leased

T = TypeVar("T")
R = TypeVar("R")


def side_by_side(jobs: Mapping[str, Callable[[dict[str, str]], T]]) -> dict[str, T]:
    """Each of ``jobs`` called with the environment its launch adds (``launch_scenario(env=...)``), all at
    once, each on a ROS domain leased for it (:mod:`domains`); their results by name. The first
    exception is raised once every job has ended (a launch stops by itself: its own timeout)."""
    with leased(len(jobs)) as envs, ThreadPoolExecutor(max_workers=len(jobs)) as pool:
        futures = {name: pool.submit(job, env) for (name, job), env in zip(jobs.items(), envs, strict=True)}
        return {name: future.result() for name, future in futures.items()}


def selected_tests(request: pytest.FixtureRequest) -> set[str]:
    """The names of the test functions of the requesting module that this run selected (what a module
    fixture needs to launch: the runs of deselected tests are left out)."""
    return {item.originalname for item in request.session.items
            if item.module is request.module and isinstance(item, pytest.Function)}


@contextmanager
def in_background(job: Callable[[dict[str, str]], T]) -> Iterator[Future[T]]:
    """``job`` (a launch, say) started in a thread with the environment of a ROS domain leased for it
    (:mod:`domains`), while the tests go on: its future. The context waits for it on the way out, so
    that nothing of it outlives the fixture (nor its lease)."""
    with leased(1) as envs, ThreadPoolExecutor(max_workers=1) as pool:
        yield pool.submit(job, envs[0])


def meanwhile(background: Callable[[], T], foreground: Callable[[], R]) -> tuple[T, R]:
    """``background()`` in a thread (launches: their processes do the work) while this thread runs
    ``foreground()`` (an in-process run, say); both results, once both have ended."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        future = pool.submit(background)
        here = foreground()
        return future.result(), here
