"""Tasks: scalar or vector task functions f(q, t) with bounds, one per file (issue 39; docs/limits.md).

* :mod:`.base`: what a task is (:class:`TaskRows`, :class:`Task`) and how the rows become one
  QP (:func:`assemble_problem`, paper 001 eq (12)-(14));
* :mod:`.relative_pose`: paper 000's relative pose task, eq (8)-(13) (type ``relative_pose``: a held target);
* :mod:`.absolute_pose`: the two tools' absolute pose (the cooperative task space; type ``absolute_pose``);
* :mod:`.circle`, :mod:`.cone`, :mod:`.manipulability`, :mod:`.table`: paper 001's f_1-3, f_4, f_5, f_6;
* :mod:`.registry`: task types by name for task scenarios, a user's own from their own file.

A new task is one file here plus its import below (the import registers its type).
"""

from dualarm_control.tasks.absolute_pose import (
    AbsolutePoseTask,
    AbsoluteState,
    grasp_state,
    halfway_state,
)
from dualarm_control.tasks.base import (
    DEFAULT_EQUALITY_WEIGHT,
    DEFAULT_INEQUALITY_WEIGHT,
    EQUALITY,
    INEQUALITY,
    PRIORITIES,
    Kind,
    SecondPriority,
    Task,
    TaskRows,
    assemble_problem,
    check_gain_weight,
    evaluate_tasks,
)
from dualarm_control.tasks.circle import CircleTask
from dualarm_control.tasks.cone import ConeTask
from dualarm_control.tasks.manipulability import ManipulabilityTask, manipulability
from dualarm_control.tasks.registry import (
    TaskContext,
    TaskSpec,
    build_task,
    check_task_type,
    register_task,
    task_types,
)
from dualarm_control.tasks.relative_pose import (
    FixedTarget,
    RelativePoseTask,
    RelativeTarget,
    relative_pose_rows,
)
from dualarm_control.tasks.table import UP, TablePlaneTask

__all__ = [
    "DEFAULT_EQUALITY_WEIGHT",
    "DEFAULT_INEQUALITY_WEIGHT",
    "EQUALITY",
    "INEQUALITY",
    "PRIORITIES",
    "UP",
    "AbsolutePoseTask",
    "AbsoluteState",
    "CircleTask",
    "ConeTask",
    "FixedTarget",
    "Kind",
    "ManipulabilityTask",
    "RelativePoseTask",
    "RelativeTarget",
    "SecondPriority",
    "TablePlaneTask",
    "Task",
    "TaskContext",
    "TaskRows",
    "TaskSpec",
    "assemble_problem",
    "build_task",
    "check_gain_weight",
    "check_task_type",
    "evaluate_tasks",
    "grasp_state",
    "halfway_state",
    "manipulability",
    "register_task",
    "relative_pose_rows",
    "task_types",
]
