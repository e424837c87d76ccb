"""The brake at a stall (dualarm_control/limits/stall.py; docs/collision.md, "At a stall"): while a collision or
live-obstacle row holds the command, and 0.1 s after, the row limits add the joint acceleration bound
(``collision.stall_acceleration``, 10 rad/s^2 by default). Without it the commands alternate from one cycle
to the next at a stall (collision_demo's first goal, standard QP: 69.7 rad/s^2 between two cycles)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.collision import CollisionModel
from dualarm_control.collision.live import LiveObstacle
from dualarm_control.controller import RelativeController
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import ParameterError
from dualarm_control.kinematics import Configuration, DualArmModel
from dualarm_control.limits.acceleration import acceleration_box
from dualarm_control.limits.live import LiveObstacleLimit
from dualarm_control.limits.stall import StallBrake
from dualarm_control.scenario import load_scenario

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

FIRST_GOAL = str(Path(__file__).parent / "data" / "collision_demo_first_goal.yaml")
SAFETY = 0.03


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


def test_the_brake_holds_for_0_1_s_after_the_last_active_row_and_gives_the_acceleration_box(
        model: DualArmModel) -> None:
    controller = RelativeController(model, controller_params({"solver": "standard_qp"}))
    brake = controller.limit("collision").brake  # type: ignore[attr-defined]
    assert isinstance(brake, StallBrake) and brake.hold == 20  # 0.1 s at T = 5 ms
    q, previous = model.description.ready, np.linspace(-0.5, 0.5, model.nq)
    assert brake.box(q, previous) is None  # released: nothing
    brake.saw(0)
    assert brake.box(q, previous) is None
    brake.saw(2)
    boxes = [brake.box(q, previous) for _ in range(21)]
    assert all(b is not None for b in boxes[:20]) and boxes[20] is None
    expected = acceleration_box(q, brake.limits, previous, np.full(model.nq, 10.0), 0.005)
    assert boxes[0] is not None and all(np.array_equal(a, b) for a, b in zip(boxes[0], expected, strict=True))
    brake.saw(1)
    controller.reset()
    assert brake.box(q, previous) is None  # a new run starts released


def test_stall_acceleration_0_leaves_the_brake_out_and_bad_values_are_refused(model: DualArmModel) -> None:
    off = RelativeController(model, controller_params({"solver": "standard_qp", "collision.stall_acceleration": 0.0}))
    assert off.limit("collision").brake is None  # type: ignore[attr-defined]
    for bad in (-1.0, float("nan")):
        with pytest.raises(ParameterError, match="collision.stall_acceleration"):
            controller_params({"solver": "standard_qp", "collision.stall_acceleration": bad})


def test_the_brake_ends_the_limit_cycle_at_a_stall() -> None:
    """collision_demo's first goal drives the right arm through the left one; the standard QP stalls at the
    safety distance. Without the brake its commands change by 69.7 rad/s^2 from one cycle to the next there;
    with it by at most the bound, and the stall and its distance are as before."""
    scenario = load_scenario(FIRST_GOAL)
    model = DualArmModel(scenario.robot)
    peaks, records = {}, {}
    for stall in (0.0, 10.0):
        params = controller_params({"solver": "standard_qp", "collision.stall_acceleration": stall})
        records[stall] = record = run_scenario(scenario, params, model)
        peaks[stall] = float(np.abs(np.diff(record.commands, axis=0)).max() / record.period)
    print(f"largest change between two cycles: {peaks[0.0]:.1f} rad/s^2 without the brake, {peaks[10.0]:.6f} with")
    assert peaks[0.0] > 50.0, peaks  # the limit cycle is there to be ended
    assert peaks[10.0] <= 10.0 * (1 + 1e-9), peaks
    from dualarm_control.app.record.report import summarize_run

    summary = summarize_run(records[10.0], scenario, model)
    assert ": stalled: collision constraint: " in str(summary["goal_outcomes"]), summary["goal_outcomes"]
    assert summary["collision_min_distance_m"] >= SAFETY - 1e-3, summary["collision_min_pair"]
    assert summary["solver_failures"] == 0


def test_the_live_obstacle_limit_brakes_after_an_active_row(model: DualArmModel) -> None:
    """A sphere 4 cm from the left flange: a command that meets its row at the bound holds the brake, and the
    next cycle's constraint carries the acceleration box around that command."""
    import coal

    params = controller_params({"solver": "standard_qp", "collision.live_obstacles": 1})
    controller = RelativeController(model, params)
    limit = controller.limit("live_obstacles")
    assert isinstance(limit, LiveObstacleLimit) and limit.brake is not None
    q = model.description.ready
    conf = Configuration(model, q)
    flange = conf.frame("left_flange").position
    limit.feed.publish((LiveObstacle.make("ball", coal.Sphere(0.05), np.eye(3), flange + [0.0, 0.0, 0.16]),))
    zero = np.zeros(model.nq)
    first = limit.constraints(conf, zero)
    assert first.rows is not None and first.lower is None  # rows, no box yet
    a, b = first.rows.matrix[0], first.rows.bound[0]
    pressing = a * (b / float(a @ a)) * (1 + 1e-3)  # A_0 qd just over b_0: the row holds it
    report = limit.report(pressing)
    assert report is not None and report.active >= 1
    braked = limit.constraints(conf, pressing)
    expected = acceleration_box(q, limit.brake.limits, pressing, np.full(model.nq, 10.0), params.period)
    assert braked.lower is not None and braked.upper is not None
    assert np.array_equal(braked.lower, expected[0]) and np.array_equal(braked.upper, expected[1])


def test_a_collision_model_shared_by_both_row_limits_gives_each_its_own_brake(model: DualArmModel) -> None:
    controller = RelativeController(model, controller_params({"solver": "sparse_qp", "collision.live_obstacles": 2}))
    brakes = [controller.limit(name).brake for name in ("collision", "live_obstacles")]  # type: ignore[attr-defined]
    assert all(isinstance(b, StallBrake) for b in brakes) and brakes[0] is not brakes[1]
    assert isinstance(controller.collision_model, CollisionModel)


def test_a_live_parameter_change_during_a_stall_keeps_the_brake_and_the_obstacles(model: DualArmModel) -> None:
    """A controller built with new parameters takes over each limit's state from the running one
    (``RelativeController.continue_from``): a stall's brake holds on for the cycles it had left (before, the new
    brake started released, and the first cycle after the change could jump by any amount the box allows), and
    the live obstacles' feed goes on (the node's intake fills it)."""
    import coal

    values = {"solver": "standard_qp", "collision.live_obstacles": 1}
    running = RelativeController(model, controller_params(values))
    live = running.limit("live_obstacles")
    assert isinstance(live, LiveObstacleLimit) and live.brake is not None
    live.feed.publish((LiveObstacle.make("ball", coal.Sphere(0.05), np.eye(3), np.array([0.9, 0.0, 1.2])),))
    running.limit("collision").brake.saw(1)  # type: ignore[attr-defined]  # a stall: held for 20 cycles
    for _ in range(5):
        running.limit("collision").brake.box(model.description.ready, np.zeros(model.nq))  # type: ignore[attr-defined]
    live.brake.saw(2)
    changed = RelativeController(model, controller_params({**values, "solver": "sparse_qp"})).continue_from(running)
    assert changed.limit("collision").brake.left == 15  # type: ignore[attr-defined]
    new_live = changed.limit("live_obstacles")
    assert isinstance(new_live, LiveObstacleLimit) and new_live.brake is not None and new_live.brake.left == 20
    assert new_live.feed is live.feed and [o.name for o in new_live.feed.snapshot()] == ["ball"]
    previous = np.linspace(-0.3, 0.3, model.nq)
    changed._previous = previous
    braked = changed.limit("collision").constraints(Configuration(model, model.description.ready), previous)
    assert braked.lower is not None and braked.upper is not None  # the box from the first cycle on
    off = RelativeController(model, controller_params({**values, "collision.stall_acceleration": 0.0}))
    assert off.continue_from(running).limit("collision").brake is None  # type: ignore[attr-defined]
