"""Seeing the cell: ``dualarm view`` (Rerun: live, from a bag, web or saved) and its helpers."""
