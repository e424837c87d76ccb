"""Offline planning of relative paths (paper 003): index, corner path, baseline, global optimisation.

Pure functions on numpy + pinocchio + scipy; no rclpy, no simulator.
"""
