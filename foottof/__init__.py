"""foottof: quadruped locomotion over discrete terrain with foot-mounted ToF sensing (JAX + MJX)."""

__version__ = "0.1.0"
