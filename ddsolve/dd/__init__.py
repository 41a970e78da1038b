"""The decomposition: the interface Σ, the constraints and their KKT check, the multiplier methods."""
