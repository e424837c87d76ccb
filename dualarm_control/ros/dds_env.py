"""DDS environment defaults: keep traffic on this machine unless the user decides otherwise.

Cyclone DDS reads ``CYCLONEDDS_URI`` when the first ``DomainParticipant`` of a domain
is created, so :func:`apply_loopback_default` must run before that; importing
:mod:`dualarm_control.ros` does it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping
from pathlib import Path

#: Name of the shipped Cyclone DDS configuration in ``config/``.
LOOPBACK_CONFIG = "cyclonedds_loopback.xml"

#: The same configuration inline, used only if the shipped file cannot be found.
LOOPBACK_XML = (
    "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>50</MaxAutoParticipantIndex>"
    "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery></Domain></CycloneDDS>"
)

_USER_KEYS = ("CYCLONEDDS_URI", "ROS_AUTOMATIC_DISCOVERY_RANGE")


def loopback_config_path() -> Path:
    """Absolute path of ``config/cyclonedds_loopback.xml`` (source tree or install)."""
    from dualarm_control.paths import config_path

    return config_path(LOOPBACK_CONFIG).resolve()


def loopback_uri() -> str:
    """``file://`` URI of the loopback config, or the XML inline if the file is missing."""
    path = loopback_config_path()
    if path.is_file():
        return path.as_uri()
    return LOOPBACK_XML


def apply_loopback_default(env: MutableMapping[str, str] = os.environ) -> None:
    """Point ``CYCLONEDDS_URI`` at the loopback config unless the user configured DDS.

    Nothing changes when ``CYCLONEDDS_URI`` or ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is
    already set (non-empty). Call before any ``DomainParticipant`` exists.
    """
    if any(env.get(key) for key in _USER_KEYS):
        return
    env["CYCLONEDDS_URI"] = loopback_uri()


def apply_discovery_range(env: MutableMapping[str, str] = os.environ) -> None:
    """Translate ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` for plain Cyclone DDS.

    rmw implementations read that variable themselves; the Cyclone backend does not,
    so ``LOCALHOST`` (with no ``CYCLONEDDS_URI``) gets the loopback config. Other
    values leave Cyclone's defaults (network discovery) in place.
    """
    if env.get("CYCLONEDDS_URI"):
        return
    if env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper() == "LOCALHOST":
        env["CYCLONEDDS_URI"] = loopback_uri()


def domain_id(env: Mapping[str, str] = os.environ) -> int:
    """The DDS domain id from ``ROS_DOMAIN_ID`` (default 0), validated like ROS (0..232)."""
    raw = env.get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    try:
        value = int(raw)
    except ValueError:
        raise ValueError(f"ROS_DOMAIN_ID must be an integer 0..232, got {raw!r}") from None
    if not 0 <= value <= 232:
        raise ValueError(f"ROS_DOMAIN_ID must be an integer 0..232, got {value}")
    return value
