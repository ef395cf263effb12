"""Motion analysis: joint roles, motion beats, kinetic energy, foot contacts, the motion database."""
