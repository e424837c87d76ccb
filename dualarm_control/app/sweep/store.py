"""The sweep's Parquet dataset: one part file per batch of rows, written atomically.

A part is written to ``DIR/.part-*.tmp`` and renamed to ``DIR/part-<time>-<uuid>.parquet``
(``os.replace``): a reader, a crash or Ctrl-C never sees half a file. The keys done are the
``key`` column of every part; a key found twice (a run finished by two workers after a worker
loss) is read once (the first part's row).
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dualarm_control.app.sweep.run import COLUMNS, KEY_COLUMNS

STRING_COLUMNS = ("key", "robot", "solver", "variant", "error")
INT_COLUMNS = ("seed", "task", "steps")
SCHEMA = pa.schema([(c, pa.string() if c in STRING_COLUMNS else pa.int64() if c in INT_COLUMNS else pa.float64())
                    for c in COLUMNS])


def parts(out: Path) -> list[Path]:
    """The dataset's part files, oldest first."""
    return sorted(out.glob("part-*.parquet"))


def write_part(out: Path, rows: Sequence[dict[str, Any]]) -> Path | None:
    """Write ``rows`` as one part file (atomic rename); None for no rows."""
    if not rows:
        return None
    out.mkdir(parents=True, exist_ok=True)
    table = pa.Table.from_pylist([{c: row.get(c) for c in COLUMNS} for row in rows], schema=SCHEMA)
    name = f"part-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet"
    tmp = out / f".{name}.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, out / name)
    return out / name


def read_table(out: Path) -> pa.Table:
    """Every row of the dataset, one per key (the first written), sorted by the key columns."""
    files = parts(out)
    if not files:
        return SCHEMA.empty_table()
    table = pa.concat_tables([pq.read_table(f, schema=SCHEMA) for f in files])
    keys = table.column("key").to_pylist()
    first: dict[str, int] = {}
    for i, key in enumerate(keys):
        first.setdefault(key, i)
    table = table.take(sorted(first.values()))
    return table.sort_by([(c, "ascending") for c in KEY_COLUMNS])


def done_keys(out: Path) -> set[str]:
    """The keys that have a row."""
    return {k for f in parts(out) for k in pq.read_table(f, columns=["key"]).column("key").to_pylist()}
