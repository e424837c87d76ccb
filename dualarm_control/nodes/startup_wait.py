"""controller_node before its first command: waiting for a consistent joint state, and the hardware
profile's check against the graph (``hardware.startup_check``). ROS-free: the node asks the graph.

Real time, no consistent joint state yet: a zero command every tick with why it waits (the joint-state
topics' publishers, deliveries, refusals, missing joints, stamps; looked up once a second), WARN;
ERROR (the safe state) past ``hardware.startup_check`` or :data:`STARTUP_WAIT_S`. With a startup check,
no motion until the profile matches the graph; past its deadline the controller is refused.
"""

from __future__ import annotations

import time
from collections.abc import Callable

STARTUP_WAIT_S = 10.0
"""Real time: no consistent joint state this long after the start (no startup_check) is an ERROR [s]."""
CHECK_PERIOD_S = 0.1
"""``hardware.startup_check``: the graph is checked this often until it matches [s]."""
CAUSE_PERIOD_S = 1.0
"""Why the node waits is looked up this often [s]."""


class StartupWait:
    """The wait for the first consistent joint state and the startup check of ``check_s`` [s] (0: none),
    on the monotonic clock from construction."""

    def __init__(self, check_s: float) -> None:
        self.started = time.monotonic()
        self.next_cause = 0.0
        self.text = "waiting for joint_states"
        self.deadline = check_s or STARTUP_WAIT_S  # no consistent joint state by then: ERROR
        self.check_deadline: float | None = self.started + check_s if check_s > 0 else None
        """Monotonic [s] by which the profile must match the graph; None: checked (or no check)."""

    @property
    def checking(self) -> bool:
        """The profile is not known to match the graph yet: no motion."""
        return self.check_deadline is not None

    def waiting(self, cause: Callable[[], str]) -> tuple[str, bool]:
        """Why no command moves the arms yet (``cause()``: what explains it, '' if nothing; asked once a
        second), and whether the wait is past its deadline (then an ERROR: the safe state)."""
        now = time.monotonic()
        if now >= self.next_cause:
            self.next_cause = now + CAUSE_PERIOD_S
            found = cause()
            self.text = f"waiting for joint_states{f': {found}' if found else ''}"
        if now - self.started > self.deadline:
            return f"{self.text} (none consistent after {self.deadline:g} s)", True
        return self.text, False

    def matched(self) -> None:
        """The profile matches the graph: the check is over (commands may move the arms)."""
        self.check_deadline = None

    @property
    def expired(self) -> bool:
        """The startup check's deadline has passed without a match."""
        return self.check_deadline is not None and time.monotonic() > self.check_deadline
