"""Reading a child process's output line by line with a deadline (never a blocking ``readline()``).

:func:`read_line` reads the next line of a process's stdout straight from the pipe (``select`` and
one byte at a time, so nothing is read ahead: ``communicate`` or a later call gets the rest). It
waits with :func:`waiting.wait_until`: on the deadline, or when the process closes its output, it
fails (AssertionError) naming what it waited for and what it saw (the partial line, the exit code
and, once the process has exited, its stderr if that is a pipe).
"""

from __future__ import annotations

import os
import select
import subprocess

from waiting import DEADLINE_S, wait_until


def read_line(proc: subprocess.Popen[str], *, what: str, timeout: float = DEADLINE_S) -> str:
    """The next line of ``proc``'s stdout (without its end of line), read within ``timeout`` [s]."""
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    got = bytearray()
    closed: list[bool] = []

    def line() -> str | None:
        while not closed and select.select([fd], [], [], 0)[0]:
            byte = os.read(fd, 1)
            if not byte:
                closed.append(True)
            elif byte == b"\n":
                return got.decode(errors="replace") + "\n"  # truthy even for an empty line
            else:
                got.extend(byte)
        return None

    def seen() -> str:
        code = proc.poll()
        text = f"stdout so far {bytes(got)!r}; exit code {code}"
        if code is not None and proc.stderr is not None:
            text += "; stderr:\n" + proc.stderr.read()[-3000:]
        return text

    def gone() -> str | None:
        return "its stdout closed" if closed else None

    return wait_until(line, seen, what=what, timeout=timeout, gone=gone).rstrip("\n")
