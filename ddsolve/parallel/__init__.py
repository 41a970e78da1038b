"""PETSc and MPI: blocks as PETSc solvers, message passing, launching ranks."""
