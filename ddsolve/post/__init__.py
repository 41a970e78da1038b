"""Results and what is computed from them: analysis, error estimate, energy release rate, plots."""
