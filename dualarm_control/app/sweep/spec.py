"""The sweep spec (``config/sweeps/*.yaml``): the grid robots x solvers x variants x tasks, validated.

File format (every key under ``sweep:``; docs/sweep.md)::

    sweep:
      name: smoke
      scenario: assembly          # the cell, motion limits and allowed pairs the tasks run in
      robots: [lwr4_cell]         # config/robots/ names or YAML paths
      solvers: [standard_qp, sparse_qp, hierarchical_sparse_qp]
      variants: {default: {}}     # variant name -> controller_node parameters (gain, alpha, ...)
      tasks: 3                    # N (--tasks overrides)
      seed: 0
      settle_time: 0.5            # [s] after the trajectory
      batch_size: 10              # rows per Parquet part file
      retries: 3                  # Dask retries of a run on worker loss
      sampling: {...}             # TaskSampling fields (angles as goal_rotation_deg)

A bad key or value is a :class:`SpecError` naming the key (``sweep.sampling.clearance``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import yaml

from dualarm_control.app.sweep.tasks import TaskSampling
from dualarm_control.controller import ControllerParams
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import DualArmError
from dualarm_control.scenario import load_scenario


class SpecError(DualArmError):
    """A sweep spec with a bad key or value (the message names it)."""


SAMPLING_KEYS = tuple(f.name for f in fields(TaskSampling) if f.name != "goal_rotation") + ("goal_rotation_deg",)


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep spec (module docstring)."""

    name: str
    scenario: str = "assembly"
    robots: tuple[str, ...] = ("lwr4_cell",)
    solvers: tuple[str, ...] = ("standard_qp", "sparse_qp", "hierarchical_sparse_qp")
    variants: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = (("default", ()),)
    tasks: int = 10
    seed: int = 0
    settle_time: float = 0.5
    batch_size: int = 10
    retries: int = 3
    sampling: TaskSampling = field(default_factory=TaskSampling)

    def __post_init__(self) -> None:
        for key in ("tasks", "batch_size"):
            if getattr(self, key) < 1:
                raise SpecError(f"sweep.{key}: got {getattr(self, key)!r}, expected an integer >= 1")
        for key in ("seed", "retries"):
            if getattr(self, key) < 0:
                raise SpecError(f"sweep.{key}: got {getattr(self, key)!r}, expected an integer >= 0")
        if not (math.isfinite(self.settle_time) and self.settle_time >= 0):
            raise SpecError(f"sweep.settle_time: got {self.settle_time!r}, expected a number >= 0 [s]")
        for key in ("robots", "solvers", "variants"):
            if not getattr(self, key):
                raise SpecError(f"sweep.{key}: empty, expected at least one")

    def with_tasks(self, tasks: int | None) -> SweepSpec:
        """The spec with ``--tasks`` applied (None: unchanged)."""
        return self if tasks is None else replace(self, tasks=tasks)

    def with_robots(self, robots: str | None) -> SweepSpec:
        """The spec with ``--robots NAME,...`` applied (a subset of its robots; None: unchanged)."""
        if robots is None:
            return self
        chosen = tuple(r.strip() for r in robots.split(",") if r.strip())
        unknown = [r for r in chosen if r not in self.robots]
        if not chosen or unknown:
            raise SpecError(f"--robots {robots!r}: expected some of the spec's robots: {', '.join(self.robots)}")
        return replace(self, robots=chosen)

    def params(self, robot: str, solver: str, variant: str) -> ControllerParams:
        """Controller parameters of one grid cell: the cell's defaults (the scenario's on the robot:
        :meth:`~dualarm_control.scenario.Scenario.controller_defaults`), the variant's, the solver."""
        overrides = dict(dict(self.variants)[variant])
        try:
            return controller_params({**cell_defaults(self.scenario, robot), **overrides, "solver": solver})
        except (ValueError, DualArmError) as exc:
            raise SpecError(f"sweep.variants.{variant} with solver {solver!r} on {robot!r}: {exc}") from None


@lru_cache(maxsize=16)
def cell_defaults(scenario: str, robot: str) -> Mapping[str, Any]:
    """The controller defaults of ``scenario`` on ``robot`` (read once per pair; not to be modified)."""
    return load_scenario(scenario, robot).controller_defaults()


def _integer(raw: Mapping[str, Any], key: str, default: int) -> int:
    value = raw.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int):
        raise SpecError(f"sweep.{key}: got {value!r}, expected an integer")
    return value


def _names(raw: Mapping[str, Any], key: str, default: tuple[str, ...]) -> tuple[str, ...]:
    value = raw.get(key, list(default))
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise SpecError(f"sweep.{key}: got {value!r}, expected a list of names")
    return tuple(value)


def _sampling(raw: Any) -> TaskSampling:
    if not isinstance(raw, Mapping):
        raise SpecError(f"sweep.sampling: got {raw!r}, expected a mapping of {', '.join(SAMPLING_KEYS)}")
    values: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in SAMPLING_KEYS:
            raise SpecError(f"sweep.sampling.{key}: unknown key; valid keys: {', '.join(SAMPLING_KEYS)}")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SpecError(f"sweep.sampling.{key}: got {value!r}, expected a number")
        if key == "goal_rotation_deg":
            values["goal_rotation"] = math.radians(value)
        else:
            values[key] = int(value) if key == "max_attempts" else float(value)
    try:
        return TaskSampling(**values)
    except ValueError as exc:
        raise SpecError(f"sweep.sampling.{exc}") from None


def _variants(raw: Any) -> tuple[tuple[str, tuple[tuple[str, Any], ...]], ...]:
    if not isinstance(raw, Mapping) or not raw:
        raise SpecError(f"sweep.variants: got {raw!r}, expected a mapping name -> controller parameters")
    out = []
    for name, params in raw.items():
        if not isinstance(params, Mapping):
            raise SpecError(f"sweep.variants.{name}: got {params!r}, expected a mapping of controller parameters")
        out.append((str(name), tuple(sorted((str(k), v if not isinstance(v, list) else tuple(v))
                                            for k, v in params.items()))))
    return tuple(out)


SPEC_KEYS = ("name", "scenario", "robots", "solvers", "variants", "tasks", "seed", "settle_time", "batch_size",
             "retries", "sampling")


def parse_spec(raw: Any, default_name: str = "sweep") -> SweepSpec:
    """A SweepSpec from the mapping under ``sweep:``; SpecError naming a bad key or value."""
    if not isinstance(raw, Mapping):
        raise SpecError(f"sweep: got {raw!r}, expected a mapping")
    unknown = sorted(set(raw) - set(SPEC_KEYS))
    if unknown:
        raise SpecError(f"sweep.{unknown[0]}: unknown key; valid keys: {', '.join(SPEC_KEYS)}")
    settle = raw.get("settle_time", 0.5)
    if isinstance(settle, bool) or not isinstance(settle, int | float):
        raise SpecError(f"sweep.settle_time: got {settle!r}, expected a number [s]")
    defaults = SweepSpec(name=default_name)
    spec = SweepSpec(
        name=str(raw.get("name", default_name)),
        scenario=str(raw.get("scenario", defaults.scenario)),
        robots=_names(raw, "robots", defaults.robots),
        solvers=_names(raw, "solvers", defaults.solvers),
        variants=_variants(raw.get("variants", {"default": {}})),
        tasks=_integer(raw, "tasks", defaults.tasks),
        seed=_integer(raw, "seed", defaults.seed),
        settle_time=float(settle),
        batch_size=_integer(raw, "batch_size", defaults.batch_size),
        retries=_integer(raw, "retries", defaults.retries),
        sampling=_sampling(raw.get("sampling", {})),
    )
    for robot in spec.robots:  # every grid cell's parameters, before anything runs
        for solver in spec.solvers:
            for variant, _ in spec.variants:
                collision = spec.params(robot, solver, variant).collision
                safety = collision.kept_distances[1]
                if collision.enabled and spec.sampling.clearance < safety:
                    raise SpecError(
                        f"sweep.sampling.clearance: {spec.sampling.clearance:g} m is below the collision limit's "
                        f"safety distance {safety:g} m (collision.safety_distance + 2 shape_margin) of "
                        f"variant {variant!r} with {solver!r} on {robot!r}: a start or goal that close "
                        "stops at the limit instead of being reached")
    return spec


def load_spec(path: Path) -> SweepSpec:
    """Read and validate a sweep spec file (SpecError naming the file and the key)."""
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SpecError(f"{path}: {exc}") from None
    if not isinstance(doc, Mapping) or "sweep" not in doc:
        raise SpecError(f"{path}: expected a top-level 'sweep:' mapping")
    try:
        return parse_spec(doc["sweep"], path.stem)
    except SpecError as exc:
        raise SpecError(f"{path}: {exc}") from None
