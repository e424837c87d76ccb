"""Progress output of long runs on stderr (experiments, plans, benchmarks)."""

from __future__ import annotations

import sys
from collections.abc import Callable

BAR_WIDTH = 30


def progress_bar(label: str) -> Callable[[float, str], None]:
    """Progress on stderr: a live bar on a terminal, a line per 10 % otherwise."""
    tty = sys.stderr.isatty()
    state = {"last": -1}

    def show(fraction: float, stage: str) -> None:
        pct = int(fraction * 100)
        filled = round(fraction * BAR_WIDTH)
        bar = "#" * filled + "." * (BAR_WIDTH - filled)
        if tty:
            print(f"\r[{label}] [{bar}] {pct:3d}% {stage:<12}", end="" if pct < 100 else "\n",
                  file=sys.stderr, flush=True)
        elif pct // 10 != state["last"] // 10:
            print(f"[{label}] [{bar}] {pct:3d}% ({stage})", file=sys.stderr, flush=True)
        state["last"] = pct

    return show
