"""Solves: the domain-decomposition driver, the monolithic reference, adaptivity, sweeps."""
