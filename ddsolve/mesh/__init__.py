"""Meshes: the two halves and Σ, the reference cells, and geometry (box, gmsh, mesh files)."""
