"""``dualarm hardware``: a hardware profile against a live ros2_control graph (issue 29, docs/hardware.md)."""
