"""Finite elements: assembly of the blocks' stiffness matrices and loads, fields of a solution."""
