"""The robot's distance to a horizontal table plane, paper 001 eq (11) (scenario task type ``table``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.collision import sphere_plane_distances, witness_rows
from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import Configuration, FloatArray
from dualarm_control.tasks.base import (
    DEFAULT_INEQUALITY_WEIGHT,
    INEQUALITY,
    Kind,
    TaskRows,
    check_gain_weight,
)
from dualarm_control.tasks.registry import TaskContext, TaskSpec, register_task

UP = np.array([0.0, 0.0, 1.0])
"""The table plane's outward normal (world z)."""


@dataclass(frozen=True)
class TablePlaneTask:
    """Distance of the robot to a horizontal table plane, paper 001 eq (11) (one row per point).

    The robot is represented by spheres (frame origin, radius r_j) as the paper suggests;
    f_6 = -min_j (z_j - r_j - z_table) <= b_6 < 0 is written as one row per sphere,
    f_6j = -(z_j - r_j - z_table) <= b_6 (the same feasible set, each row smooth):
    df_6j/dq = -(J_v,j)_z, df/dt = 0.

    Attributes:
        points: (frame, radius [m]) pairs. table_height: z of the table top in the world [m].
        bound: b_6 < 0: minus the smallest allowed clearance [m].
    """

    points: tuple[tuple[str, float], ...]
    table_height: float
    bound: float
    gain: float
    weight: float = DEFAULT_INEQUALITY_WEIGHT
    name: str = "table"
    kind: Kind = INEQUALITY

    def __post_init__(self) -> None:
        check_gain_weight(self.name, self.gain, self.weight)
        if not self.points or any(not (math.isfinite(r) and r >= 0) for _, r in self.points):
            raise ValueError(f"task {self.name!r}: points must be (frame, radius >= 0) pairs, got {self.points}")
        if not (math.isfinite(self.bound) and self.bound < 0):
            raise ValueError(f"task {self.name!r}: bound b_6 must be < 0, got {self.bound}")

    def distances(self, conf: Configuration) -> FloatArray:
        """Clearance z_j - r_j - z_table of every sphere [m], (m,)."""
        return self._distances(conf)[0]

    def _distances(self, conf: Configuration) -> tuple[FloatArray, FloatArray]:
        """The spheres' clearances [m] (m,) and their normals from sphere to table (m, 3), from the
        collision limit's distance code (:func:`~dualarm_control.collision.sphere_plane_distances`)."""
        centres = np.array([conf.frame(f).position for f, _ in self.points])
        radii = np.array([r for _, r in self.points])
        d, _, normals = sphere_plane_distances(centres, radii, UP, self.table_height)
        return d, normals

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        """f_6j = -d_j, df_6j/dq = -dd_dq: the collision limit's row (:func:`~dualarm_control.collision.witness_rows`)
        of the sphere's lowest point, which moves with the frame: (-n)^T J_v + ((-r up) x (-n))^T J_w =
        (J_v)_z, the second term zero (up and -n are parallel)."""
        d, normals = self._distances(conf)
        jac = np.array([-witness_rows(-normals[j:j + 1], -r * UP[None, :], conf.frame(f).jacobian)[0]
                        for j, (f, r) in enumerate(self.points)])
        m = len(self.points)
        return TaskRows(self.name, self.kind, -d, np.full(m, self.bound), jac, np.zeros(m),
                        self.gain, self.weight)


@register_task("table")
def table(spec: TaskSpec, context: TaskContext) -> TablePlaneTask:
    """``frames`` and ``radii`` [m] (spheres), ``bound`` (b_6 < 0, m); the plane at the scenario's table height."""
    if context.table_height is None:
        raise ScenarioError(f"scenario task {spec.name!r}: a table task needs 'scenario.table_height'")
    frames, radii = spec.value("frames", list), spec.value("radii", list)
    if len(frames) != len(radii):
        raise ScenarioError(f"scenario parameter 'scenario.{spec.name}': {len(frames)} frames but "
                            f"{len(radii)} radii")
    return TablePlaneTask(tuple(zip(frames, (float(r) for r in radii), strict=True)), context.table_height,
                          bound=spec.value("bound", float), gain=context.gain,
                          weight=spec.value("weight", float, DEFAULT_INEQUALITY_WEIGHT), name=spec.name)
