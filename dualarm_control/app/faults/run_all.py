"""The whole fault matrix: every group of rows in turn (matrix.py's groups and profile_kills.py's).

Above both modules so that neither imports the other's caller (profile_kills.py builds on matrix.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

from dualarm_control.app.faults.matrix import (
    Row,
    collision_rows,
    link_rows,
    loopback_rows,
    loss_rows,
)
from dualarm_control.app.faults.profile_kills import profile_kill_rows
from dualarm_control.app.faults.rows import ROWS


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
