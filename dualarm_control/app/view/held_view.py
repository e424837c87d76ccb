"""A held object in the Rerun viewer (issue 41, item 4): its box on its frame and the wrist forces as arrows.

Entities: ``/frames/<name>/box`` (a ``Boxes3D`` in the coordinate frame ``<name>``, the held object's, which
:func:`~dualarm_control.app.view.rerun_view.log_frames` places in the left tool frame) and
``/frames/<tool>/wrench`` (an ``Arrows3D`` per cycle from the tool frame's origin: the force the hand exerts on
the object, the wrist reading in the tool frame [N] times :data:`ARROW_M_PER_N`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray

ARROW_M_PER_N = 0.01
"""Arrow length per newton [m/N]: the 2 kg box's 9.8 N per hand draws 9.8 cm."""


@dataclass(frozen=True)
class HeldDrawing:
    """What the viewer draws of a held object.

    Attributes:
        name: the held object's frame (its pose is among the run's frames). size: its box's sides [m], (3,).
        forces: per tool frame (``left_tool``, ``right_tool``) the wrist force per cycle in that frame [N], (N, 3)
            (NaN: no reading of that cycle's stamp).
    """

    name: str
    size: tuple[float, float, float]
    forces: Mapping[str, FloatArray] = field(default_factory=dict)

    def log(self, stamps: FloatArray, recording: Any = None) -> None:
        """Log the box (static) and the arrows (per cycle) on the ``time`` timeline."""
        import rerun as rr

        from dualarm_control.app.view.rerun_view import _time

        half = [0.5 * s for s in self.size]
        rr.log(f"frames/{self.name}/box", rr.Boxes3D(half_sizes=[half], colors=[(50, 120, 230)]),
               rr.CoordinateFrame(self.name), static=True, recording=recording)
        stamps = np.asarray(stamps, dtype=float)
        for tool, forces in self.forces.items():
            forces = np.asarray(forces, dtype=float).reshape(-1, 3)
            keep = np.isfinite(forces).all(axis=1)
            if not keep.any():
                continue
            n = int(keep.sum())
            rr.log(f"frames/{tool}/wrench", rr.CoordinateFrame(tool), static=True, recording=recording)
            columns = rr.Arrows3D.columns(vectors=ARROW_M_PER_N * forces[keep], origins=np.zeros((n, 3)))
            rr.send_columns(f"frames/{tool}/wrench", indexes=[_time(stamps[keep])], columns=columns.partition([1] * n),
                            recording=recording)


def wrist_forces(wrists: Mapping[str, Mapping[int, FloatArray]], stamps: list[int]) -> dict[str, FloatArray]:
    """Per tool frame the wrist force [N] (N, 3) at each cycle's stamp [ns] from a bag's wrist readings
    (``/left/wrench``, ``/right/wrench`` by header stamp; NaN where a stamp has none)."""
    out = {}
    for topic, tool in (("/left/wrench", "left_tool"), ("/right/wrench", "right_tool")):
        readings = wrists.get(topic, {})
        out[tool] = np.array([readings[s][:3] if s in readings else np.full(3, np.nan) for s in stamps])
    return out
