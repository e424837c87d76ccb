"""Seeing the cell: ``dualarm view`` (Rerun: live, from a bag, web or saved; a video of a bag; a Foxglove
WebSocket server) and its helpers."""
