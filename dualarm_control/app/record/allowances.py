"""Which of a scenario's allowed contacts a run used, part by part (issue 40 item 2).

Contacts belong to the task: a scenario allows link pairs (``scenario.collision_allowed``, e.g. the
assembly's ``left_tool right_tool``: the two end effectors, the peg in the hole), which the collision
limit then never checks. A run says which of them it used: for each part of the run (each segment of a
relative trajectory, else the whole run), the closest of the pairs the scenario's allowance removed
(those the robot's own collision model checks), its distance [m], and ``used`` when it came under the
safety distance d_s (where the collision limit would have held the arms), else ``not used``.

The distances are coal's, on a collision model of exactly those pairs (the robot's model minus the
scenario's), at every :data:`STRIDE`-th recorded cycle and the final positions.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.collision import DEFAULT_MARGIN, CollisionModel, CollisionParams
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import Scenario

STRIDE = 4
"""Every how many recorded cycles the allowed pairs' distances are computed (20 ms at 200 Hz)."""
ALLOWANCE_KEYS = ("allowances_used", "allowance_outcomes")


def allowed_by_scenario(scenario: Scenario, model: DualArmModel) -> CollisionModel | None:
    """A collision model whose pairs are exactly those the robot's own model checks and the scenario's
    allowance removes (None when it removes none); shared per robot model, built once."""
    robot = CollisionModel.shared(model, model.description.collision_allowed)
    kept = set(scenario.collision_model(model).pairs)
    if kept >= set(robot.pairs):
        return None
    return CollisionModel.shared(model, (*model.description.collision_allowed, *kept))


def allowance_outcomes(scenario: Scenario, model: DualArmModel, time: FloatArray, positions: FloatArray,
                       final: FloatArray, parts: Sequence[tuple[str, float]],
                       safety: float = CollisionParams().safety_distance) -> list[tuple[str, str, float, bool]]:
    """For each part (its label and end time [s]; the last one ends with the run), the closest allowed pair
    (``"link_a – link_b"``), its distance [m] and whether it came under ``safety`` [m]: (label, pair,
    distance, used). Empty when the scenario allows nothing. ``time`` (N,) [s], ``positions`` (N, n) [rad],
    ``final`` (n,) [rad]."""
    allowed = allowed_by_scenario(scenario, model)
    if allowed is None:
        return []
    samples = [(float(t), q) for t, q in zip(time[::STRIDE], positions[::STRIDE], strict=True)]
    samples.append((math.inf, np.asarray(final, dtype=float)))
    out = []
    k, best = 0, (math.inf, "")
    ends = [end for _, end in parts[:-1]] + [math.inf]
    for t, q in samples:
        while t > ends[k]:
            out.append((parts[k][0], best[1], best[0], best[0] < safety))
            k, best = k + 1, (math.inf, "")
        if not np.all(np.isfinite(q)):
            continue
        near = allowed.near(q, within=allowed.margin, rows=False)
        if len(near.distance):
            i = int(np.argmin(near.distance))
            if near.distance[i] < best[0]:
                best = (float(near.distance[i]), " – ".join(near.links[i]))
    out.append((parts[k][0], best[1], best[0], best[0] < safety))
    while len(out) < len(parts):  # parts after the last sample
        out.append((parts[len(out)][0], "", math.inf, False))
    return out


def allowance_metrics(scenario: Scenario, model: DualArmModel, time: FloatArray, positions: FloatArray,
                      final: FloatArray, parts: Sequence[tuple[str, float]]) -> dict[str, str]:
    """The metrics.json keys (:data:`ALLOWANCE_KEYS`): the scenario's allowed pairs as given, and each part's
    outcome, e.g. "segment 2 'insert': used: left_hole_wall_xp – right_peg at 0.0050 m" ({} without any)."""
    found = allowance_outcomes(scenario, model, time, positions, final, parts)
    if not found:
        return {}

    def text(label: str, pair: str, distance: float, used: bool) -> str:
        if not pair:
            return f"{label}: not used (no allowed pair within {DEFAULT_MARGIN} m)"
        return f"{label}: {'used' if used else 'not used'}: closest {pair} at {distance:.4f} m"

    return {"allowances_used": ", ".join(f"{a} {b}" for a, b in scenario.collision_allowed),
            "allowance_outcomes": " | ".join(text(*row) for row in found)}


def allowance_lines(label: str, summary: Mapping[str, object]) -> list[str]:
    """The terminal's lines for a run's allowances ([] without any)."""
    if "allowance_outcomes" not in summary:
        return []
    return [f"{label}: allowed contacts {summary['allowances_used']} (the scenario's)"] + \
        [f"  {line}" for line in str(summary["allowance_outcomes"]).split(" | ")]
