"""A child process that must not outlive its parent (Linux ``PR_SET_PDEATHSIG``).

Used by the nodes under ``dualarm launch`` (:func:`dualarm_control.ros.env.stop_with_launcher`) and by the
planner's worker processes (``dualarm plan``): a parent that dies, even by SIGKILL, takes them with it.
"""

from __future__ import annotations

import os
import signal

PR_SET_PDEATHSIG = 1
"""prctl(2) option: the signal this process gets when its parent thread dies."""


def stop_with_parent(parent: int, sig: int = signal.SIGTERM) -> bool:
    """Ask the kernel for ``sig`` when the process ``parent`` (this process's parent, its pid) dies; if it has
    died already (this process re-parented before the request), send ``sig`` to this process now. False where
    the request cannot be made (no prctl: not Linux), and nothing is done."""
    import ctypes

    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, int(sig))
    except (OSError, AttributeError):
        return False
    if os.getppid() != parent:
        os.kill(os.getpid(), sig)
    return True
