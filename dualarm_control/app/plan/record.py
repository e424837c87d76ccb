"""plan.json: the self-describing document of paper 003's plan.

``format``, ``units``, ``joint_names``, the sampled path and the planner settings travel with the
configurations, so a node can execute it without this package's planner: ``configurations`` are the
joint positions [rad] at the path samples ``path.positions_m`` (in the left tool frame F1, orientation
``path.rotation``), in the order of ``joint_names``.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from dualarm_control.collision import CollisionModel
from dualarm_control.drive_monitor import closest_pair
from dualarm_control.kinematics import DualArmModel
from dualarm_control.planning.plan_file import PLAN_FORMAT

if TYPE_CHECKING:  # the planner and the simulator are only imported where a plan is made or executed
    from dualarm_control.app.plan.execute import ExecutionResult
    from dualarm_control.app.plan.optimise import PlanResult


def plan_record(result: PlanResult, model: DualArmModel, execution: ExecutionResult | None) -> dict[str, Any]:
    """The plan.json document of paper 003's plan (see the module docstring)."""
    cfg = result.config
    path = cfg.corner.sample()
    c = cfg.corner
    points = []
    for i in range(len(path)):
        points.append({
            "index": i + 1,
            "key_point": (i + 1) in cfg.key_points,
            "position_m": path.positions[i].tolist(),
            "tangent": path.tangents[i].tolist(),
            "index_value": float(result.indices[i]),
            "baseline_index_value": float(result.baseline.indices[i]),
            "closure_error_m": float(result.closure_position_errors[i]),
            "closure_error_rad": float(result.closure_rotation_errors[i]),
            "configuration_rad": result.configurations[i].tolist(),
            "baseline_configuration_rad": result.baseline.configurations[i].tolist(),
        })
    doc: dict[str, Any] = {
        "format": PLAN_FORMAT,
        "description": "Global manipulability plan of a relative path (Faroni et al., eq 14-20) and the "
                       "pseudo-inverse baseline (eq 12-13) from the same first configuration.",
        "scenario": cfg.name,
        "scenario_file": str(cfg.source) if cfg.source else None,
        "units": {"configurations": "rad", "positions": "m (right tool in the left tool frame F1)",
                  "index": "m^2/rad^2, c = u^T J_r J_r^T u with u = [t; 0] (eq 14), lower is better",
                  "runtime_s": "s wall clock"},
        "joint_names": model.joint_names,
        "average_index": result.average_index,
        "baseline_average_index": result.baseline_average_index,
        "index_ratio": result.average_index / result.baseline_average_index,
        "max_closure_error_m": float(np.max(result.closure_position_errors)),
        "max_closure_error_rad": float(np.max(result.closure_rotation_errors)),
        "joint_limit_violations": result.joint_limit_violations,
        "baseline_joint_limit_violations": int(np.sum((result.baseline.configurations < model.q_min)
                                                      | (result.baseline.configurations > model.q_max))),
        "baseline_max_closure_error_m": float(np.max(result.baseline.position_errors)),
        "runtime_s": result.runtime_s,
        "baseline_runtime_s": result.baseline_runtime_s,
        "starts": cfg.starts,
        "inner_starts": min(cfg.starts, cfg.inner_starts),
        "seed": cfg.seed,
        "workers": result.workers,
        "path": {
            "kind": "corner",
            "side_m": c.side, "fillet_radius_m": c.fillet_radius, "height_m": c.height,
            "samples": list(c.samples), "rpy_rad": list(c.rpy),
            "rotation": path.rotation.tolist(),
            "positions_m": path.positions.tolist(),
            "tangents": path.tangents.tolist(),
            "key_points": list(cfg.key_points),
        },
        "parameters": {
            "lambda_key": cfg.lambda_key, "lambda_inner": cfg.lambda_inner, "candidates": cfg.candidates,
            "inner_spread_rad": cfg.inner_spread,
            "baseline": asdict(cfg.baseline),
            "execution": {"gain": cfg.execution_gain, "velocity_scale": cfg.execution_velocity_scale,
                          "subdivisions": cfg.execution_subdivisions, "settle_time": cfg.execution_settle},
        },
        "indices": result.indices.tolist(),
        "baseline_indices": result.baseline.indices.tolist(),
        "configurations": result.configurations.tolist(),
        "points": points,
        "key_stage": {"best_start": result.best_key_start, "values": result.key_values.tolist(),
                      "start_values": result.key_start_values.tolist(),
                      "candidates": cfg.candidates, "candidate_starts": result.candidate_starts,
                      "candidate_whole_path_costs": result.candidate_costs},
        "inner_stage": {"best_starts": result.best_inner_starts, "values": result.inner_values.tolist()},
        "initial_configuration_study": {
            "planned_first_configuration_average_index": result.baseline_average_index,
            "random_first_configurations_average_index": [float(np.mean(b.indices)) for b in result.random_baselines],
            "random_first_configurations_rad": [b.configurations[0].tolist() for b in result.random_baselines],
        },
    }
    closest = closest_pair(CollisionModel.shared(model, model.description.collision_allowed), result.configurations)
    doc["closest_pair_m"], doc["closest_pair"], doc["closest_pair_point"] = closest.distance, closest.text, closest.index + 1
    if execution is not None:
        doc["executed_max_error_m"] = execution.max_error_m
        doc["executed_max_error_rad"] = execution.max_error_rad
        doc["execution"] = asdict(execution)
    return doc
