"""``dualarm view``: the cell seen from a bag or a live run (Rerun, video, Foxglove)."""
