"""Reference sources of a scenario (what the controller follows): see :mod:`dualarm_control.references.base`."""
