"""ddsolve: domain decomposition for a two-layer elastic structure with a non-penetrating crack."""

__version__ = "0.1.0"
