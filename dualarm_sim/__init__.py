"""dualarm_sim: a pybullet simulation of the dual-arm cell, velocity-commanded like KUKA FRI.

The package root is ROS-free (numpy + pybullet only); ``dualarm_sim.cell`` holds the
step-driven simulator. The ROS shell around it lives in ``dualarm_sim.sim_node``.
"""

from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig
from dualarm_sim.samples import CommandReport, JointSample

__all__ = ["CellConfig", "CommandReport", "DualArmCell", "JointSample"]
