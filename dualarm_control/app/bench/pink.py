"""The same relative task solved by pink (``pip install '.[bench]'``), for the benchmark.

pink's differential IK: a ``RelativeFrameTask`` (right tool in the left tool frame, cost
1 per m and per rad) plus a ``PostureTask`` (cost 1e-3, target = current q) for the
null space, with pink's default configuration and velocity limits, one ``solve_ik`` per
cycle of T = 5 ms. Two set-ups are timed: the fastest found (``Configuration.update`` in
place, the given QP solver) and pink's documented default (a new ``Configuration`` per
call, proxqp).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from dualarm_control.kinematics import LEFT_TOOL, RIGHT_TOOL, DualArmModel

PERIOD = 0.005
"""s: pink's dt (one control period)."""


def pink_version() -> str | None:
    """pink's version, or None when it is not installed."""
    try:
        import pink
    except ImportError:
        return None
    return str(getattr(pink, "__version__", "unknown"))


def pink_cycle(model: DualArmModel, solver: str, update_in_place: bool) -> Callable[[Any], None]:
    """A callable that runs one pink cycle (kinematics + QP) for a benchmark case (q, target)."""
    import pink
    import pinocchio as pin
    from pink.tasks import PostureTask, RelativeFrameTask

    data = model.model.createData()
    relative = RelativeFrameTask(RIGHT_TOOL, LEFT_TOOL, position_cost=1.0, orientation_cost=1.0)
    posture = PostureTask(cost=1e-3)
    configuration = pink.Configuration(model.model, data, (model.q_min + model.q_max) / 2.0)

    def cycle(case: Any) -> None:
        if update_in_place:
            configuration.update(case.q)
            conf = configuration
        else:
            conf = pink.Configuration(model.model, data, case.q)
        relative.set_target(pin.SE3(case.target.rotation, case.target.position))
        posture.set_target(case.q)
        pink.solve_ik(conf, [relative, posture], PERIOD, solver=solver, safety_break=False)

    return cycle
