"""Planner settings read from a scenario file (``scenario.corner.*``, ``scenario.plan.*``, ...).

The corner-path scenario (config/scenarios/corner_path.yaml) is an ordinary scenario (initial
configuration and pose segments, so the nodes can load it by name) with these extra keys:

* ``corner.side`` [m], ``corner.fillet_radius`` [m], ``corner.height`` [m] (plane z in F1),
  ``corner.samples`` [h1, h2, h3], ``corner.rpy_deg`` (R_d) — Sect. IV-B of paper 003;
* ``plan.key_points`` (1-based, Gamma of eq 15), ``plan.lambda_key`` (eq 19),
  ``plan.lambda_inner`` (eq 20), ``plan.starts``, ``plan.inner_starts``, ``plan.candidates``, ``plan.seed``, ``plan.inner_spread_rad``
  (std. dev. of the random perturbation of the inner starts);
* ``baseline.k0`` (eq 13), ``baseline.gain`` [1/s], ``baseline.speed`` [m/s];
* ``execution.gain`` [1/s] (joint tracking), ``execution.velocity_scale``,
  ``execution.settle_time`` [s], ``execution.subdivisions``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dualarm_control.errors import ScenarioError
from dualarm_control.params import ParameterError, read_params_file
from dualarm_control.planning.baseline import BaselineParams
from dualarm_control.planning.path import CornerPath
from dualarm_control.robot import RobotDescription
from dualarm_control.robot_params import load_robot
from dualarm_control.scenario import scenario_file, scenario_robot
from dualarm_control.scenario_keys import number


@dataclass(frozen=True)
class PlanConfig:
    """Validated planner settings (defaults: paper 003, Sect. IV-C).

    Attributes:
        name: scenario name.
        corner: path geometry.
        key_points: Gamma, 1-based path indices, increasing, first = 1 and last = h.
        lambda_key, lambda_inner: smoothness weights of eq (19) and (20).
        starts: random starts of the key-point NLP (eq 19).
        inner_starts: starts per inner NLP (eq 20), capped at ``starts``.
        candidates: best distinct key-point optima completed by stage 2; the complete plan of
            lowest whole-path cost is kept (1 = the paper's method).
        seed: base seed of all random starts.
        inner_spread: std. dev. [rad] of the perturbation of inner starts 1.. (start 0 is
            the plain interpolation).
        baseline: parameters of the pseudo-inverse baseline.
        execution_gain: K of qd = qd_ref + K (q_ref - q) [1/s].
        execution_velocity_scale: share of the joint velocity limits used by the reference.
        execution_settle: simulated time after the trajectory [s].
        execution_subdivisions: knots per path interval of the executed trajectory (>= 1).
        source: the file.
        robot: the robot planned for (the scenario's, or ``--robot``).
    """

    name: str = "corner_path"
    corner: CornerPath = field(default_factory=CornerPath)
    key_points: tuple[int, ...] = (1, 7, 13, 19, 25, 31)
    lambda_key: float = 1.5
    lambda_inner: float = 3.0
    starts: int = 100
    inner_starts: int = 10
    candidates: int = 4
    seed: int = 0
    inner_spread: float = 0.2
    baseline: BaselineParams = field(default_factory=BaselineParams)
    execution_gain: float = 30.0
    execution_velocity_scale: float = 0.5
    execution_settle: float = 0.5
    execution_subdivisions: int = 8
    source: Path | None = None
    robot: RobotDescription = field(default_factory=load_robot)

    def __post_init__(self) -> None:
        h = sum(self.corner.samples)
        keys = self.key_points
        if len(keys) < 2 or keys[0] != 1 or keys[-1] != h or any(b <= a for a, b in itertools.pairwise(keys)):
            raise ScenarioError(f"plan.key_points: got {list(keys)}, expected increasing 1-based indices from 1 to {h}")
        if self.execution_subdivisions < 1:
            raise ScenarioError(f"execution.subdivisions: got {self.execution_subdivisions}, expected >= 1")
        if min(self.starts, self.inner_starts, self.candidates) < 1:
            raise ScenarioError(f"plan.starts / inner_starts / candidates: got {self.starts} / {self.inner_starts} / "
                                f"{self.candidates}, expected >= 1")
        for key in ("lambda_key", "lambda_inner", "inner_spread"):
            if not (math.isfinite(getattr(self, key)) and getattr(self, key) >= 0):
                raise ScenarioError(f"plan.{key}: got {getattr(self, key)}, expected a number >= 0")

    @property
    def key_indices(self) -> tuple[int, ...]:
        """Gamma as 0-based indices."""
        return tuple(k - 1 for k in self.key_points)


def _ints(flat: dict[str, Any], key: str, default: tuple[int, ...]) -> tuple[int, ...]:
    value = flat.get("scenario." + key, list(default))
    if not isinstance(value, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise ScenarioError(f"scenario parameter 'scenario.{key}': got {value!r}, expected a list of integers")
    return tuple(value)


def load_plan_config(name_or_path: str, robot: str | RobotDescription | None = None) -> PlanConfig:
    """Planner settings of a scenario (registry name or YAML path) on its robot or on ``robot``;
    missing keys take the defaults.

    Raises:
        ScenarioError: unknown scenario, no ``scenario.corner.*`` keys, or an invalid value.
    """
    path = scenario_file(name_or_path)
    try:
        flat = read_params_file(path, "planner")
    except ParameterError as exc:
        raise ScenarioError(str(exc)) from None
    if not any(k.startswith("scenario.corner.") for k in flat):
        raise ScenarioError(f"scenario {name_or_path!r} ({path}) has no 'scenario.corner.*' path to plan")
    d = PlanConfig()
    rpy = flat.get("scenario.corner.rpy_deg", [180.0, 0.0, 0.0])
    if not isinstance(rpy, list) or len(rpy) != 3:
        raise ScenarioError(f"scenario parameter 'scenario.corner.rpy_deg': got {rpy!r}, expected 3 numbers")
    samples = _ints(flat, "corner.samples", d.corner.samples)
    if len(samples) != 3:
        raise ScenarioError(f"scenario parameter 'scenario.corner.samples': got {list(samples)}, expected [h1, h2, h3]")
    try:
        corner = CornerPath(
            side=number(flat, "corner.side", d.corner.side),
            fillet_radius=number(flat, "corner.fillet_radius", d.corner.fillet_radius),
            height=number(flat, "corner.height", d.corner.height),
            samples=(samples[0], samples[1], samples[2]),
            rpy=(math.radians(rpy[0]), math.radians(rpy[1]), math.radians(rpy[2])),
        )
    except ValueError as exc:
        raise ScenarioError(f"scenario.corner: {exc}") from None
    return PlanConfig(
        name=str(flat.get("scenario.name", path.stem)),
        corner=corner,
        key_points=_ints(flat, "plan.key_points", d.key_points),
        lambda_key=number(flat, "plan.lambda_key", d.lambda_key),
        lambda_inner=number(flat, "plan.lambda_inner", d.lambda_inner),
        starts=int(number(flat, "plan.starts", d.starts)),
        inner_starts=int(number(flat, "plan.inner_starts", d.inner_starts)),
        candidates=int(number(flat, "plan.candidates", d.candidates)),
        seed=int(number(flat, "plan.seed", d.seed)),
        inner_spread=number(flat, "plan.inner_spread_rad", d.inner_spread),
        baseline=BaselineParams(
            k0=number(flat, "baseline.k0", d.baseline.k0),
            gain=number(flat, "baseline.gain", d.baseline.gain),
            speed=number(flat, "baseline.speed", d.baseline.speed),
        ),
        execution_gain=number(flat, "execution.gain", d.execution_gain),
        execution_velocity_scale=number(flat, "execution.velocity_scale", d.execution_velocity_scale),
        execution_settle=number(flat, "execution.settle_time", d.execution_settle),
        execution_subdivisions=int(number(flat, "execution.subdivisions", d.execution_subdivisions)),
        source=path,
        robot=scenario_robot(flat, path, robot)[0],
    )
