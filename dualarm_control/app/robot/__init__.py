"""``dualarm robot``: list, show and check robot descriptions, and find ready positions."""
