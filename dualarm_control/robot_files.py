"""A robot description's files, and :class:`RobotError`.

Where the URDF a description names is (``example-robot-data:<path under robots/>``, a file name in
the package's ``urdf/``, or a path), where its ``package://`` meshes are, and the cache the
resolved URDFs are written to (:mod:`dualarm_control.robot`). Errors name the ``robot.`` key
(:mod:`dualarm_control.robot_params`).
"""

from __future__ import annotations

import hashlib
import os
import re
import sysconfig
from pathlib import Path

from dualarm_control.errors import DualArmError
from dualarm_control.paths import share_dir

PREFIX = "robot."
ERD_SCHEME = "example-robot-data:"


class RobotError(DualArmError, ValueError):
    """A robot description that cannot be used: the message names the key and the value."""


def _key(key: str) -> str:
    return f"'{PREFIX}{key}'"


def example_robot_data_dir() -> Path:
    """``<site-packages>/cmeel.prefix/share/example-robot-data`` (the ``robots`` extra)."""
    for key in ("purelib", "platlib"):
        candidate = Path(sysconfig.get_paths()[key]) / "cmeel.prefix" / "share" / "example-robot-data"
        if candidate.is_dir():
            return candidate
    raise RobotError("example-robot-data is not installed: pip install -e '.[robots]' (or pip install "
                     "example-robot-data)")


def urdf_file(value: str, base: Path) -> Path:
    """The URDF a description's ``urdf`` names: ``example-robot-data:<path under robots/>``, a
    file name in the package's ``urdf/``, or a path (relative to the description's folder)."""
    if value.startswith(ERD_SCHEME):
        path = example_robot_data_dir() / "robots" / value[len(ERD_SCHEME):]
    elif "/" not in value and (share_dir() / "urdf" / value).is_file():
        path = share_dir() / "urdf" / value
    else:
        path = Path(value) if Path(value).is_absolute() else base / value
    if not path.is_file():
        raise RobotError(f"robot parameter {_key('urdf')}: got {value!r}: no such file {path}")
    return path.resolve()


def package_dirs(urdf: Path) -> list[Path]:
    """Where ``package://NAME/...`` may point: example-robot-data's share, the ament index's
    shares (ROS_PACKAGE_PATH, AMENT_PREFIX_PATH), the URDF's own ancestors."""
    dirs: list[Path] = []
    try:
        dirs.append(example_robot_data_dir().parent)
    except RobotError:
        pass
    for var in ("ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH"):
        for entry in filter(None, os.environ.get(var, "").split(os.pathsep)):
            dirs += [Path(entry), Path(entry) / "share"]
    return dirs + list(urdf.parents)


def mesh_path(filename: str, urdf: Path) -> Path:
    """Absolute path of a mesh ``filename`` of ``urdf`` (RobotError naming it when missing)."""
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://"):].partition("/")
        for d in package_dirs(urdf):
            if (d / package / rest).is_file():
                return (d / package / rest).resolve()
            if d.name == package and (d / rest).is_file():
                return (d / rest).resolve()
        raise RobotError(f"robot parameter {_key('urdf')}: {urdf.name}: mesh {filename!r} not found "
                         f"(package {package!r} in none of: {', '.join(str(d) for d in package_dirs(urdf)[:4])}, ...)")
    path = Path(filename.removeprefix("file://"))
    path = path if path.is_absolute() else urdf.parent / path
    if not path.is_file():
        raise RobotError(f"robot parameter {_key('urdf')}: {urdf.name}: mesh {filename!r} not found ({path})")
    return path.resolve()


def cache_dir() -> Path:
    """Where resolved URDFs are written: ``$XDG_CACHE_HOME/dualarm_control/urdf`` (~/.cache)."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "dualarm_control" / "urdf"


def _cached_file(name: str, xml: str) -> Path:
    """A file holding ``xml``, named by its content (so every process of a run finds the same)."""
    digest = hashlib.sha256(xml.encode()).hexdigest()[:16]
    path = cache_dir() / f"{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}-{digest}.urdf"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(xml)
        os.replace(tmp, path)
    return path
