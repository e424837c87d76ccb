"""``dualarm faults``: every group of rows in one run (:mod:`~dualarm_control.app.faults.matrix` holds the
loopback, loss, link and collision rows; :mod:`~dualarm_control.app.faults.profile_kills` the controller kills on
the shipped hardware profiles)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

from dualarm_control.app.faults.matrix import (
    ROWS,
    Row,
    collision_rows,
    link_rows,
    loopback_rows,
    loss_rows,
)
from dualarm_control.app.faults.profile_kills import profile_kill_rows


def run_matrix(out: Path, scenario: str = "assembly", only: Sequence[str] = ROWS,
               say: Callable[[str], None] = print) -> list[Row]:
    """Run the selected rows; each row's outcome as soon as it is known."""
    unknown = [n for n in only if n not in ROWS]
    if unknown:
        raise ValueError(f"unknown fault rows {', '.join(unknown)}; valid: {', '.join(ROWS)}")
    rows: list[Row] = []
    for group in (loopback_rows, profile_kill_rows, loss_rows, link_rows, collision_rows):
        t = time.monotonic()
        got = group(out, scenario, only, say)
        for row in got:
            say(f"[{row.status}] {row.name}: {row.observed}")
        if got:
            say(f"({time.monotonic() - t:.0f} s)")
        rows += got
    return sorted(rows, key=lambda r: ROWS.index(r.name))
