"""Mechanics of the cheap models: statics, dynamics, modes, homogenisation, anisotropy measures."""
