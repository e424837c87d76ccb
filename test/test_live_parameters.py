"""Live parameter changes keep the controller's state (issue 25), in one process.

The assembly task on the pybullet cell with the acceleration bound (10 rad/s^2) and the
standard QP; during the motion the gain changes four times (8, 12, 6, 10) and the solver once
(standard_qp -> sparse_qp), each change made as the controller node makes it: a controller built
with the new parameters, then :meth:`RelativeController.continue_from` at the cycle boundary.
The bound |qd_k - qd_{k-1}| <= a_max T is checked on the commands themselves (beneath nothing:
no clip stands between the solver's result and what is checked but the bounds it is given), and
the same run without ``continue_from`` (the behaviour before issue 25) must break it, so the
check can fail.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from dualarm_control import controller as core
from dualarm_control.controller_params import controller_params
from dualarm_control.kinematics import DualArmModel
from dualarm_control.references.base import RunOptions
from dualarm_control.scenario import load_scenario
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

A_MAX = 10.0  # rad/s^2, config/acceleration_limit.yaml
ROUNDING = 1e-6  # rad/s^2: the QP back-end's bound tolerance (1e-9 rad/s) over T = 5 ms is 2e-7
CHANGES = {150: {"gain": 8.0}, 300: {"gain": 12.0}, 450: {"gain": 6.0}, 600: {"gain": 10.0},
           750: {"solver": "sparse_qp"}}
CYCLES = 900  # 4.5 s: the approach is under way at every change

Swap = Callable[[core.RelativeController, core.RelativeController], core.RelativeController]


def keep_state(old: core.RelativeController, new: core.RelativeController) -> core.RelativeController:
    return new.continue_from(old)


def reset_state(old: core.RelativeController, new: core.RelativeController) -> core.RelativeController:
    return new  # before issue 25: the new controller starts from rest


def run_with_changes(swap: Swap) -> tuple[np.ndarray, list[str], core.RelativeController]:
    """Commands (CYCLES, n) [rad/s] and statuses of the run; the last controller."""
    scenario = load_scenario("assembly")
    model = DualArmModel(scenario.robot)
    values: dict[str, object] = {"solver": "standard_qp", "acceleration_limit": [A_MAX]}
    params = controller_params(values)
    options = RunOptions(scenario.limits, scenario.settle_time)
    source = scenario.reference
    config = CellConfig.for_robot(scenario.robot, control_period=params.period, **source.cell(options))
    commands, statuses = [], []
    with DualArmCell(config, initial_positions=source.initial_positions(scenario.initial_positions)) as cell:
        state = cell.state()
        follower = source.follower(model, params, state.positions, options)
        for k in range(CYCLES):
            if k in CHANGES:
                values = {**values, **CHANGES[k]}
                built = core.RelativeController(model, controller_params(values))
                follower.controller = swap(follower.controller, built)
            out = follower.cycle(k * params.period, state.positions, None)
            cell.apply_command(out.velocities)
            commands.append(out.velocities.copy())
            statuses.append(out.result.status)
            state = cell.step()
    return np.array(commands), statuses, follower.controller


def largest_acceleration(commands: np.ndarray, period: float = 0.005) -> tuple[float, int]:
    """max_k max_i |qd_k - qd_{k-1}| / T [rad/s^2] from rest, and the cycle where it happens."""
    steps = np.abs(np.diff(np.vstack((np.zeros(commands.shape[1]), commands)), axis=0)).max(axis=1) / period
    return float(steps.max()), int(steps.argmax())


@pytest.fixture(scope="module")
def kept() -> tuple[np.ndarray, list[str], core.RelativeController]:
    return run_with_changes(keep_state)


def test_acceleration_bound_holds_across_live_changes(kept: tuple[np.ndarray, list[str], core.RelativeController]
                                                      ) -> None:
    commands, statuses, last = kept
    assert last.params.solver == "sparse_qp" and last.params.gain == 10.0
    assert set(statuses) == {"solved"}, sorted(set(statuses))
    peak, at = largest_acceleration(commands)
    assert peak <= A_MAX + ROUNDING, f"{peak:.4f} rad/s^2 at cycle {at} (changes at {sorted(CHANGES)})"
    # the motion is under way at every change (the changes are not made at rest)
    for k in CHANGES:
        assert np.abs(commands[k - 1]).max() > 0.05, f"at rest before the change at cycle {k}"


def test_without_continue_from_the_bound_breaks() -> None:
    """The check above can fail: the same run with controllers that start from rest."""
    commands, _, _ = run_with_changes(reset_state)
    peak, at = largest_acceleration(commands)
    assert peak > A_MAX + 1.0, f"{peak:.4f} rad/s^2 at cycle {at}"  # measured: 13.09 at cycle 450
    assert at in CHANGES, f"largest step at cycle {at}, not at a change {sorted(CHANGES)}"


def test_same_solver_keeps_its_memory_and_new_solver_is_seeded() -> None:
    model = DualArmModel()
    base = {"solver": "sparse_qp", "acceleration_limit": [A_MAX]}
    old = core.RelativeController(model, controller_params(base))
    old._previous = np.linspace(-0.1, 0.1, model.nq)
    gain_change = core.RelativeController(model, controller_params({**base, "gain": 7.0})).continue_from(old)
    assert gain_change.solver is old.solver  # warm start and proximal memory go on
    np.testing.assert_array_equal(gain_change.previous_command, old.previous_command)
    assert gain_change.previous_command is not old.previous_command
    other = core.RelativeController(model, controller_params({**base, "solver": "hierarchical_sparse_qp"}))
    other.continue_from(old)
    assert other.solver is not old.solver
    np.testing.assert_array_equal(other.solver._primary._previous, old.previous_command)  # proximal centre
    weight_change = core.RelativeController(model, controller_params({**base, "l1_weight": 1e-5}))
    assert weight_change.continue_from(old).solver is not old.solver  # other solver parameters: a new solver
