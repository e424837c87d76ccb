"""Reference sources of a scenario (what the controller follows): see :mod:`dualarm_control.references.base`."""

from dualarm_control.references.base import ReferenceSource
from dualarm_control.references.segments import SegmentSpec, SegmentsSource
from dualarm_control.references.tasks import TasksSource

__all__ = ["ReferenceSource", "SegmentSpec", "SegmentsSource", "TasksSource"]
