"""Progress output of long runs on stderr (experiments, plans): tqdm, with rate and time left.

On a terminal a live tqdm bar; otherwise (a log, CI) one line per 10 %, formatted by tqdm's
meter, so that a log is not flooded with carriage returns.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from tqdm import tqdm

STEPS = 1000  # resolution of the bar: the fraction in 0.1 % steps
BAR_FORMAT = "{desc} {percentage:3.0f}%|{bar:30}| {elapsed}<{remaining}{postfix}"


def progress_bar(label: str) -> Callable[[float, str], None]:
    """``show(fraction, stage)``: progress of a run on stderr (a live bar on a terminal, a line per 10 % otherwise).

    The bar closes itself when the fraction reaches 1.
    """
    if sys.stderr.isatty():
        bar = tqdm(total=STEPS, desc=f"[{label}]", bar_format=BAR_FORMAT, file=sys.stderr, leave=True)

        def live(fraction: float, stage: str) -> None:
            bar.set_postfix_str(stage, refresh=False)
            bar.update(round(fraction * STEPS) - bar.n)
            if bar.n >= STEPS:
                bar.close()

        return live
    start = time.monotonic()
    last = [-1]

    def lines(fraction: float, stage: str) -> None:
        pct = int(fraction * 100)
        if pct // 10 != last[0] // 10:
            meter = tqdm.format_meter(round(fraction * STEPS), STEPS, time.monotonic() - start, prefix=f"[{label}]",
                                      ascii=True, bar_format=BAR_FORMAT, postfix=f"({stage})")
            print(meter, file=sys.stderr, flush=True)
        last[0] = pct

    return lines
