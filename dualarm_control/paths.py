"""Locate the package's shared files (urdf/, config/) in a source tree, a pip or a colcon install."""

from __future__ import annotations

import sys
from pathlib import Path

from dualarm_control.errors import DualArmError

PACKAGE = "dualarm_control"


def share_dir() -> Path:
    """Return the directory that holds ``urdf/`` and ``config/``.

    Order: the source tree next to this package (editable installs, tests), the
    ament index (colcon installs), then ``<prefix>/share/dualarm_control`` (pip installs).
    """
    source = Path(__file__).resolve().parents[1]
    if (source / "urdf").is_dir() and (source / "config").is_dir():
        return source
    try:  # colcon install with ROS 2 sourced
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        pass
    else:
        try:
            return Path(get_package_share_directory(PACKAGE))
        except PackageNotFoundError:
            pass
    return Path(sys.prefix) / "share" / PACKAGE


def urdf_path() -> Path:
    """Path of the cell's URDF, loaded by pinocchio and pybullet alike."""
    return share_dir() / "urdf" / "dualarm_cell.urdf"


def config_path(*parts: str) -> Path:
    """Path inside ``config/`` (e.g. ``config_path('solvers', 'sparse_qp.yaml')``)."""
    return share_dir().joinpath("config", *parts)


def registry_names(folder: str) -> list[str]:
    """Names of the YAML files shipped in ``config/<folder>/`` (the scenarios', the robots' registry)."""
    return sorted(p.stem for p in config_path(folder).glob("*.yaml"))


def registry_file(folder: str, name_or_path: str, what: str, error: type[DualArmError], hint: str = "") -> Path:
    """The YAML of ``name_or_path``: a file path (ending .yaml/.yml) or a name of ``config/<folder>/``;
    when there is none, ``error`` (the caller's: ScenarioError, RobotError) naming ``what`` and, for an
    unknown name, the valid names followed by ``hint``."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise error(f"{what} file not found: {path}")
        return path
    candidate = config_path(folder, f"{name_or_path}.yaml")
    if candidate.is_file():
        return candidate
    raise error(f"unknown {what} {name_or_path!r}; valid choices: {', '.join(registry_names(folder))}{hint}")
