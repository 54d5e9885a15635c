"""springbench: score and calibrate spring/mass models against linear elasticity."""

__version__ = "0.1.0"
