"""Keep ROS traffic on this machine unless the user chose otherwise.

Every process the package starts runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
unless one of :data:`USER_DISCOVERY_SETTINGS` is already set (the user's own discovery
range, static peers, a Fast DDS profile...). rcl reads these variables in ``rclpy.init``,
so :func:`apply_localhost_default` must run before it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping

USER_DISCOVERY_SETTINGS = (
    "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_STATIC_PEERS",
    "ROS_LOCALHOST_ONLY",
    "FASTRTPS_DEFAULT_PROFILES_FILE",
    "FASTDDS_DEFAULT_PROFILES_FILE",
    "CYCLONEDDS_URI",
)


def localhost_environment(environ: Mapping[str, str]) -> dict[str, str]:
    """A copy of ``environ`` with the localhost discovery default added when the user set none."""
    env = dict(environ)
    if not any(env.get(key) for key in USER_DISCOVERY_SETTINGS):
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def apply_localhost_default(environ: MutableMapping[str, str] | None = None) -> None:
    """Apply :func:`localhost_environment` in place (default: this process's ``os.environ``)."""
    target = os.environ if environ is None else environ
    target.update(localhost_environment(target))


LAUNCHER_PID_VARIABLE = "DUALARM_LAUNCHER_PID"
"""Set by ``dualarm launch`` for its children: the pid whose death must stop them."""


def stop_with_launcher(environ: Mapping[str, str] | None = None) -> None:
    """Under ``dualarm launch``: get SIGTERM when the launcher dies, even by SIGKILL (Linux
    ``PR_SET_PDEATHSIG``), so that no node outlives it and keeps publishing on the domain."""
    import ctypes
    import signal

    pid = (os.environ if environ is None else environ).get(LAUNCHER_PID_VARIABLE, "")
    if not pid.isdigit():
        return
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        return
    if os.getppid() != int(pid):  # the launcher died before the request
        os.kill(os.getpid(), signal.SIGTERM)
