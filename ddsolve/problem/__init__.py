"""The problem: scenes (geometry, materials, loads, solver settings), materials and load expressions."""
