"""One control cycle of a task scenario (paper 001): tasks at gain k, optional force feedback (eq 9).

The same object serves the in-process experiment (``app/run/tasks.py``) and a node:
give it the measured joint positions, the time since the start of the task and, in the
force variant, the raw F/T sensor reading at the brush; it returns the joint velocity
command with the evaluated tasks, the filtered normal force and the offset f_F.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.controller import ControllerParams, RelativeController, TaskOutput
from dualarm_control.errors import ScenarioError
from dualarm_control.force import ForcePI, ForceSensorModel, contact_normal_force
from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.references.tasks import TasksSource
from dualarm_control.tasks import CircleTask, Task


@dataclass(frozen=True)
class TaskCycle:
    """Result of one :meth:`TasksController.step`.

    Attributes:
        output: the controller's cycle (command, solver record, evaluated tasks, cycle time).
        measured_force: filtered normal force f_c [N] the PI used (NaN without force feedback
            or when the reading was not finite).
        normal_offset: f_F of eq (9) [m] in the circle task this cycle.
    """

    output: TaskOutput
    measured_force: float
    normal_offset: float


def _check_frames(model: DualArmModel, tasks: list[Task]) -> None:
    """Evaluate every task once at q = 0 so that a frame missing from the URDF is reported
    now, naming the task (ScenarioError), not at the first control cycle."""
    conf = Configuration(model, np.zeros(model.nq))
    for task in tasks:
        try:
            task.evaluate(conf, 0.0)
        except KeyError as exc:
            raise ScenarioError(f"scenario task {task.name!r}: {exc.args[0]}") from None


class TasksController:
    """The tasks of a task scenario at gain k and, with ``force``, the force loop of eq (9):
    F/T reading -> noise and low-pass (:class:`ForceSensorModel`, the simulated sensor chain)
    -> f_c = N^T F (N and R_2 from the controller's own kinematics) -> PI -> circle offset.

    With ``force`` the circle's height includes the scenario's pan modelling error
    (``force.model_error``), which the force loop has to absorb.
    """

    def __init__(self, model: DualArmModel, params: ControllerParams, spec: TasksSource, gain: float,
                 force: bool = False) -> None:
        self.model = model
        self.spec = spec
        self.force = force
        self.period = params.period
        self.controller = RelativeController(model, params)
        self.tasks: list[Task] = spec.build_variant(gain, force)
        _check_frames(model, self.tasks)
        index = [i for i, t in enumerate(self.tasks) if isinstance(t, CircleTask)]
        if force and len(index) != 1:
            raise ValueError(f"the force variant needs exactly one circle task, the scenario has {len(index)}")
        self._circle_index = index[0] if index else -1
        self.reset()

    @property
    def circle(self) -> CircleTask | None:
        """The circle task as built (normal offset 0), or None."""
        return self._circle

    def reset(self) -> None:
        """Forget the solver's warm start, the filter state and the force integral."""
        self.controller.reset()
        circle = self.tasks[self._circle_index] if self._circle_index >= 0 else None
        self._circle: CircleTask | None = circle if isinstance(circle, CircleTask) else None
        self._sensor = ForceSensorModel(self.spec.force, self.period)
        self._pi = ForcePI(self.spec.force)
        self._offset = 0.0

    def step(self, q: FloatArray, t: float, wrench: FloatArray | None = None) -> TaskCycle:
        """One cycle at joint positions q (n,) [rad] and task time t [s].

        Args:
            wrench: force variant only: raw sensor reading [N, N m] (6,) in the tool frame
                (the wrench the flange exerts on the tool). A non-finite reading keeps the
                previous offset (the force loop holds) and gives measured_force NaN.
        """
        measured = math.nan
        tasks = self.tasks
        if self.force:
            if wrench is None:
                raise ValueError("the force variant needs the F/T reading every cycle")
            wrench = np.asarray(wrench, dtype=float)
            q = self.model.check_q(q)
            if wrench.shape == (6,) and math.isfinite(wrench.sum()) and math.isfinite(q.sum()):
                circle = self._circle
                assert circle is not None
                pan, tool = self.model.frame_poses(q, (circle.pan_frame, circle.tool_frame))
                measured = contact_normal_force(self._sensor.filter(wrench), tool.rotation, pan.rotation[:, 2],
                                                self.spec.force.tool_mass)
                self._offset = self._pi.step(measured, self.period)
            tasks = list(self.tasks)
            assert self._circle is not None
            tasks[self._circle_index] = dataclasses.replace(self._circle, normal_offset=self._offset)
        output = self.controller.solve_tasks(q, tasks, t)
        return TaskCycle(output, measured, self._offset)
