"""Terrain: heightfield container, tile generators, terrain map and curriculum."""

from foottof.terrain.heightfield import Heightfield

__all__ = ["Heightfield"]
