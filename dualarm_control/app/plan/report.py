"""plan.json and the figures of a plan (paper 003, Fig. 4 and Fig. 5).

plan.json is self-describing (``format``, ``units``, ``joint_names``, the sampled path and
the planner settings travel with the configurations), so a node can execute it without this
package's planner: ``configurations`` are the joint positions [rad] at the path samples
``path.positions_m`` (in the left tool frame F1, orientation ``path.rotation``), in the
order of ``joint_names``.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualarm_control.app.plan.optimise import PlanResult
from dualarm_control.kinematics import DualArmModel
from dualarm_control.planning.plan_file import PLAN_FORMAT

if TYPE_CHECKING:  # the simulator (pybullet) is only imported when a plan is executed
    from dualarm_control.app.plan.execute import ExecutionResult



def plan_record(result: PlanResult, model: DualArmModel, execution: ExecutionResult | None) -> dict[str, Any]:
    """The plan.json document (see the module docstring)."""
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
    if execution is not None:
        doc["executed_max_error_m"] = execution.max_error_m
        doc["executed_max_error_rad"] = execution.max_error_rad
        doc["execution"] = asdict(execution)
    return doc


def write_plan(directory: Path, doc: dict[str, Any]) -> Path:
    """Write ``directory/plan.json``; returns its path."""
    directory.mkdir(parents=True, exist_ok=True)
    out = directory / "plan.json"
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return out


def plot_indices(result: PlanResult, out: Path) -> None:
    """Fig. 4: c along the path for the global method and the baseline from the same start."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    i = np.arange(1, len(result.indices) + 1)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(i, result.indices, "b.-", label=f"global method (mean {result.average_index:.3f})")
    ax.plot(i, result.baseline.indices, "r.-", label=f"pseudo-inverse + null-space gradient (mean "
            f"{result.baseline_average_index:.3f})")
    for k in result.config.key_points:
        ax.axvline(k, color="0.85", lw=0.8, zorder=0)
    h1, h2, _ = result.config.corner.samples
    ax.axvspan(h1 + 0.5, h1 + h2 + 0.5, color="y", alpha=0.15, label="fillet")
    ax.set_xlabel("path point i (grey: key points)")
    ax.set_ylabel(r"$c = u^T J_r J_r^T u$ [m$^2$/rad$^2$]")
    ax.set_title(f"{result.config.name}: index along the path (paper Fig. 4), {result.config.starts} starts, "
                 f"{result.config.candidates} candidates")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def plot_initial_configurations(result: PlanResult, out: Path) -> None:
    """Fig. 5: the baseline from the planned first configuration vs random feasible ones."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    i = np.arange(1, len(result.indices) + 1)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(i, result.baseline.indices, "b.-",
            label=f"from the planned q_1 (mean {result.baseline_average_index:.3f})")
    for b, color in zip(result.random_baselines, ("r", "g", "m", "c", "k"), strict=False):
        ax.plot(i, b.indices, color + ".-", label=f"from a random feasible q_1 (mean {np.mean(b.indices):.3f})")
    ax.set_xlabel("path point i")
    ax.set_ylabel(r"$c$ [m$^2$/rad$^2$]")
    ax.set_title("pseudo-inverse baseline: effect of the initial configuration (paper Fig. 5)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
