"""Running: the one in-process runner, the launcher of the node processes, progress bars."""

DEFAULT_SOLVERS = "standard_qp,sparse_qp,hierarchical_sparse_qp"
"""The solvers ``dualarm experiment`` compares when none is named (Table I of paper 000)."""
