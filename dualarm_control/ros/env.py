"""Keep ROS traffic on this machine unless the user chose otherwise, and discover peers quickly.

Every process the package starts runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
unless one of :data:`USER_DISCOVERY_SETTINGS` is already set (the user's own discovery
range, static peers, a Fast DDS profile...). rcl reads these variables in ``rclpy.init``,
so :func:`apply_localhost_default` must run before it.

:func:`apply_discovery_profile` points Fast DDS at the package's participant profile
(``config/fastdds_discovery.xml``) unless the user chose a Fast DDS profile: it makes every
participant announce itself every 0.1 s instead of Fast DDS's 3 s. A participant that
joins a running graph can lose the reply of a peer that discovered it at once (Fast DDS
2.14 sends its first announcement before it registers its receivers, and the peer does not
answer its later announcements). The two then know of each other only at the peer's next
periodic announcement: up to 3.3 s without the matching topics (docs/bench.md,
"Start-up"). The same profile sends every participant's user data over UDP, never through
shared memory, where a peer SIGKILLed mid-message stalled its writers for seconds (docs/safety.md,
"A peer killed mid-message"). Fast DDS reads the variable when rclpy creates the participant,
so this too must run before the first node.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping
from pathlib import Path

from dualarm_control.paths import config_path

FASTDDS_PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
"""The variable Fast DDS 2.x (ROS 2 Humble, Jazzy) reads its XML profiles file from."""
FASTDDS_USER_PROFILES = (FASTDDS_PROFILE_VARIABLE, "FASTDDS_DEFAULT_PROFILES_FILE")
FASTDDS_CWD_PROFILE = "DEFAULT_FASTRTPS_PROFILES.xml"
"""Fast DDS also loads this file from the working directory: a user's profile too."""
USER_DISCOVERY_SETTINGS = (
    "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_STATIC_PEERS",
    "ROS_LOCALHOST_ONLY",
    *FASTDDS_USER_PROFILES,
    "CYCLONEDDS_URI",
)


def discovery_profile() -> Path:
    """The package's Fast DDS participant profile (fast periodic announcements, user data over UDP)."""
    return config_path("fastdds_discovery.xml")


def udp_only_env() -> dict[str, str]:
    """Loopback discovery and every participant's user data over UDPv4, named explicitly (the package's profile, so
    that no other profile brings shared memory back): what goes between the processes goes through lo, where netem
    acts (``dualarm faults``' best_effort_loss row). ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` would not do it: under
    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps sets its own transports, shared memory included."""
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", FASTDDS_PROFILE_VARIABLE: str(discovery_profile())}


def _is_package_profile(value: str) -> bool:
    try:
        return Path(value).resolve() == discovery_profile().resolve()
    except OSError:
        return False


def _user_set(environ: Mapping[str, str], key: str) -> bool:
    """``key`` set by the user (the package's own discovery profile does not count)."""
    value = environ.get(key)
    return bool(value) and not (key == FASTDDS_PROFILE_VARIABLE and _is_package_profile(str(value)))


def localhost_environment(environ: Mapping[str, str]) -> dict[str, str]:
    """A copy of ``environ`` with the localhost discovery default added when the user set none."""
    env = dict(environ)
    if not any(_user_set(env, key) for key in USER_DISCOVERY_SETTINGS):
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def apply_localhost_default(environ: MutableMapping[str, str] | None = None) -> None:
    """Apply :func:`localhost_environment` in place (default: this process's ``os.environ``)."""
    target = os.environ if environ is None else environ
    target.update(localhost_environment(target))


def apply_discovery_profile(environ: MutableMapping[str, str] | None = None, cwd: Path | None = None) -> bool:
    """Set :data:`FASTDDS_PROFILE_VARIABLE` to :func:`discovery_profile` unless the user chose a Fast DDS
    profile (a profiles-file variable, or :data:`FASTDDS_CWD_PROFILE` in ``cwd``): theirs wins. True if set."""
    target = os.environ if environ is None else environ
    if any(target.get(key) for key in FASTDDS_USER_PROFILES):
        return False
    if ((Path.cwd() if cwd is None else cwd) / FASTDDS_CWD_PROFILE).is_file() or not discovery_profile().is_file():
        return False
    target[FASTDDS_PROFILE_VARIABLE] = str(discovery_profile())
    return True


LAUNCHER_PID_VARIABLE = "DUALARM_LAUNCHER_PID"
"""Set by ``dualarm launch`` for its children: the pid whose death must stop them."""


def stop_with_launcher(environ: Mapping[str, str] | None = None) -> None:
    """Under ``dualarm launch``: get SIGTERM when the launcher dies, even by SIGKILL (Linux
    ``PR_SET_PDEATHSIG``, :func:`~dualarm_control.lifetime.stop_with_parent`), so that no node outlives it and
    keeps publishing on the domain."""
    from dualarm_control.lifetime import stop_with_parent

    pid = (os.environ if environ is None else environ).get(LAUNCHER_PID_VARIABLE, "")
    if pid.isdigit():
        stop_with_parent(int(pid))

RECORDER_NODE = "_dualarm_bag_recorder"
"""The recorder's node name (``dualarm bag record``): what a launch's trajectory node waits for (``start_after_reader``)."""
