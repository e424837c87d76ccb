"""Thin node shells: parse parameters, wire topics, call the core."""
