"""Mesh stage: the graded, rod-conforming triangle mesh of the fabric and the rods' node chains."""

from .grid import FabricMesh, RodChain, build_mesh, graded_coordinates

__all__ = ["FabricMesh", "RodChain", "build_mesh", "graded_coordinates"]
