"""ROS 2 name rules: node names, namespaces, topic expansion, remapping, DDS topic names.

Follows rcl: a relative topic ``x`` in namespace ``/ns`` is ``/ns/x``; ``~/x`` is
private (``/ns/node/x``); ``{node}`` and ``{ns}`` are substituted; remap rules are
expanded the same way and compared with the expanded name; the DDS topic of
``/ns/x`` is ``rt/ns/x`` (rmw_cyclonedds_cpp).
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from dualarm_control.errors import DualArmError

ROS_TOPIC_PREFIX = "rt"

_NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class InvalidNameError(DualArmError, ValueError):
    """A node name, namespace or topic name breaks the ROS 2 naming rules."""


def validate_node_name(name: str) -> str:
    """Return ``name`` if it is a valid ROS 2 node name (letters, digits, ``_``)."""
    if not _NODE_NAME.fullmatch(name or ""):
        raise InvalidNameError(
            f"invalid node name {name!r}: use letters, digits and '_', not starting with a digit"
        )
    return name


def normalize_namespace(namespace: str | None) -> str:
    """``None``/``''`` -> ``/``; ``ns`` -> ``/ns``; validates the tokens."""
    if not namespace:
        return "/"
    ns = namespace if namespace.startswith("/") else "/" + namespace
    if ns != "/":
        ns = ns.rstrip("/")
        _check_tokens(ns, "namespace")
    return ns


def fully_qualified_node_name(namespace: str, name: str) -> str:
    """``/ns`` + ``node`` -> ``/ns/node``."""
    return f"{namespace.rstrip('/')}/{name}"


def expand_topic_name(topic: str, node_name: str, namespace: str) -> str:
    """Expand a topic name against the node's namespace, as rcl does."""
    if not topic:
        raise InvalidNameError("topic name is empty")
    ns = normalize_namespace(namespace)
    name = topic.replace("{node}", node_name).replace("{ns}", ns).replace("{namespace}", ns)
    if name == "~" or name.startswith("~/"):
        name = fully_qualified_node_name(ns, node_name) + name[1:]
    elif not name.startswith("/"):
        name = f"{ns.rstrip('/')}/{name}"
    _check_tokens(name, "topic name", original=topic)
    return name


def remap_topic_name(
    topic: str, node_name: str, namespace: str, rules: Iterable[tuple[str, str]]
) -> str:
    """Expanded topic name after the first matching ``(src, dst)`` remap rule."""
    expanded = expand_topic_name(topic, node_name, namespace)
    for src, dst in rules:
        if expand_topic_name(src, node_name, namespace) == expanded:
            return expand_topic_name(dst, node_name, namespace)
    return expanded


def dds_topic_name(fq_topic: str) -> str:
    """``/joint_states`` -> ``rt/joint_states`` (rmw_cyclonedds_cpp naming)."""
    return ROS_TOPIC_PREFIX + fq_topic


def _check_tokens(name: str, what: str, original: str | None = None) -> None:
    shown = original if original is not None else name
    if not name.startswith("/") or (name != "/" and name.endswith("/")) or "//" in name:
        raise InvalidNameError(f"invalid {what} {shown!r}: slashes misplaced")
    for token in name.strip("/").split("/"):
        if not _TOKEN.fullmatch(token):
            raise InvalidNameError(
                f"invalid {what} {shown!r}: token {token!r} must use letters, digits and '_' "
                "and not start with a digit"
            )
