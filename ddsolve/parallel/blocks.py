"""One elasticity block as a PETSc matrix and KSP, factored once and solved many times.

Each block's KSP has the options prefix ``<block name>_`` (``u_minus_``, ``u_plus_``, ``v_minus_``,
``v_plus_``).  Code defaults (preonly + Cholesky with the method's factorization package) are set
first and ``setFromOptions`` last, so ``-u_minus_ksp_type cg -u_minus_pc_type gamg`` work from the
command line.
"""
from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import functools
import math
import os
import re
from typing import Callable

import numpy as np
from petsc4py import PETSc

from ddsolve.errors import SolverError
from ddsolve.fem.assembly import BlockSystem

_FACTOR_TYPES = ("cholesky", "lu")
_CHUNK = 64  # right-hand sides per multi-column solve when the flexibility is built by solves
#: How :meth:`Block.schur_complement` gets S, chosen per block by the PETSc option
#: ``-<block>_schur_complement`` (see :meth:`Block.factor`); the first is the default.
SCHUR_ROUTES = ("factorization", "dirichlet", "inverse", "solves")
_NONE = np.zeros(0)


def default_factor_package(preferred: str = "mumps") -> str:
    """``preferred`` if this PETSc has it, else PETSc's own factorization."""
    return preferred if preferred == "petsc" or PETSc.Sys.hasExternalPackage(preferred) else "petsc"


class Block:
    """K x = rhs + E·load for one block, where E puts a trace load onto the Σ degrees of freedom.

    The block lives on ``comm``: PETSc.COMM_SELF, or a block communicator over which its matrix is
    distributed by contiguous rows (``system`` then holds this rank's rows).  ``factor_package`` is
    the default Cholesky package (``mumps`` or ``petsc``; PETSc's own is sequential, so distributed
    blocks use MUMPS); the options ``-<name>_pc_factor_mat_solver_type`` and friends override it.
    The matrix carries the rigid-body modes as near-null space, for ``-<name>_pc_type gamg``.
    Traces, energies and solutions are collected on the block's first rank (its *leader*).

    The block is nondimensionalized: PETSc holds K/s and right-hand sides b/s, with s the power of two
    nearest the block's largest diagonal entry (:func:`diagonal_scale`), so every factorization sees
    numbers of order one whatever the moduli, and solutions come out unscaled.  Division by a power
    of two is exact, so for ordinary moduli the results are bit-identical to unscaled ones.
    """

    def __init__(self, system: BlockSystem, comm: PETSc.Comm = PETSc.COMM_SELF, factor_package: str = "mumps"):
        self.name = system.name
        self.mpi = comm.tompi4py()
        local, n = len(system.rhs), system.size
        self.scale = diagonal_scale(system, self.mpi)
        data = system.data if self.scale == 1.0 else system.data / self.scale
        csr = tuple(a.astype(PETSc.IntType, copy=False) for a in (system.indptr, system.indices)) + (data,)
        if self.mpi.size == 1:  # PETSc works on these arrays (no copy); blocks of a half share indptr, indices
            self.matrix = PETSc.Mat().createAIJWithArrays(size=((local, n), (local, n)), csr=csr,
                                                          bsize=system.block_size, comm=comm)
        else:
            self.matrix = PETSc.Mat().createAIJ(size=((local, n), (local, n)), bsize=system.block_size, csr=csr,
                                                comm=comm)
        self.matrix.setOption(PETSc.Mat.Option.SPD, True)
        if system.modes is not None:
            self._set_near_null_space(system.modes, comm)
        self.matrix_bytes = sum(a.nbytes for a in csr)  # the CSR arrays PETSc holds
        del csr
        # What the block needs later; the CSR arrays belong to the matrix now (or were copied into it).
        self.system = dataclasses.replace(system, indptr=_NONE, indices=_NONE, data=_NONE, modes=None)
        self.ksp = PETSc.KSP().create(comm=comm)
        self.ksp.setOptionsPrefix(f"{self.name}_")
        if f"{self.name}_" not in _MADE_PREFIXES:
            _MADE_PREFIXES.append(f"{self.name}_")
        self.ksp.setOperators(self.matrix)
        self.ksp.setType(PETSc.KSP.Type.PREONLY)
        pc = self.ksp.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        pc.setFactorSolverType(default_factor_package("mumps" if self.mpi.size > 1 else factor_package))
        try:
            self.ksp.setFromOptions()
        except PETSc.Error as exc:
            message = f"block {self.name}: {petsc_failure(exc, self.ksp.getOptionsPrefix())}"
            self.ksp.destroy()
            self.matrix.destroy()
            raise SolverError(message) from None
        self.rhs, self.x = self.matrix.createVecLeft(), self.matrix.createVecRight()
        self._schur: np.ndarray | None = None  # as stored by MUMPS (one triangle valid)
        self.schur_factored = False  # factored with its Schur complement on the trace (method schur)
        self.route = "dirichlet"  # how schur_complement gets S (see factor)
        self._dirichlet = self._dirichlet_matrix = self._work = None  # see factor_dirichlet
        self.kernel: np.ndarray | None = None  # a floating block's rigid motions (m, local rows), see make_floating
        self._fixed_rows = np.zeros(0, dtype=np.int64)
        self._fixed_matrix = None
        self._load_sizes = (0.0, 0.0)  # the last solve's ‖f‖∞ (this rank's rows) and ‖E load‖∞, see residual
        # The trace entries this rank owns: their positions in the trace and their local rows.
        trace = system.trace_dofs
        mine = (trace >= system.first) & (trace < system.first + local)
        self.trace_positions = np.flatnonzero(mine)
        self.trace_rows = trace[mine] - system.first
        gathered = self.mpi.gather(self.trace_positions, root=0)
        self._trace_order = np.concatenate(gathered) if self.is_leader else None
        self._trace_counts = [len(p) for p in gathered] if self.is_leader else None

    def _set_near_null_space(self, modes: np.ndarray, comm: PETSc.Comm) -> None:
        """The rigid-body modes (orthonormalized, as PETSc requires) as the matrix's near-null space."""
        vectors = []
        for mode in modes:
            v = self.matrix.createVecRight()
            v.getArray()[:] = mode
            for u in vectors:
                v.axpy(-v.dot(u), u)
            v.normalize()
            vectors.append(v)
        space = PETSc.NullSpace().create(vectors=vectors, comm=comm)
        self.matrix.setNearNullSpace(space)  # the matrix keeps its own reference
        space.destroy()
        for v in vectors:
            v.destroy()

    @property
    def trace_dofs(self) -> np.ndarray:
        return self.system.trace_dofs

    @property
    def is_leader(self) -> bool:
        return self.mpi.rank == 0

    def is_direct(self) -> bool:
        return _is_direct(self.ksp)

    def factor(self, schur: bool = False, out_of_core: bool = False) -> None:
        """Set up the solver (factorization for direct solvers); with ``out_of_core`` MUMPS keeps the factors
        on disk (:data:`MUMPS_OUT_OF_CORE`).

        With ``schur``, the option ``-<block>_schur_complement`` (one of :data:`SCHUR_ROUTES`) says how
        :meth:`schur_complement` will get S.  ``factorization`` (the default; MUMPS, one rank): MUMPS
        computes the Schur complement on the trace dofs with the factorization, so
        :meth:`schur_complement` costs no extra solves (MUMPS then orders by AMD whatever ICNTL(7)
        asks); ``dirichlet``: a plain factorization and one of the Dirichlet problem, then
        :meth:`interface_stiffness` (S itself, nothing inverted); ``inverse`` (MUMPS, one rank): a plain
        factorization (AMF), then :meth:`inverse_entries`, inverted; ``solves``: a plain factorization,
        then :meth:`flexibility`, inverted.  Blocks on several ranks, or not factored by MUMPS, take
        ``dirichlet`` unless ``solves`` is asked.

        A floating block's K is singular and never solved with: with the ``factorization`` route MUMPS
        eliminates its interior only (K_II is invertible) and hands over S; otherwise it takes
        ``dirichlet`` (a singular flexibility has no inverse) and nothing more is factored here.
        """
        pc = self.ksp.getPC()
        if schur:
            prefix = self.ksp.getOptionsPrefix() or ""
            route = PETSc.Options(prefix).getString("schur_complement", SCHUR_ROUTES[0])
            if route not in SCHUR_ROUTES:
                raise SolverError(f"-{prefix}schur_complement {route}: unknown, use one of {', '.join(SCHUR_ROUTES)}")
            whole_mumps = (self.mpi.size == 1 and self.is_direct() and pc.getFactorSolverType() == "mumps"
                           and _petsc_c() is not None)
            if not whole_mumps and route != "solves" or self.floating and route != "factorization":
                route = "dirichlet"
            self.route = route
        if not (self.floating and self._fixed_matrix is None and self.route != "factorization"):
            self._factor_operator(schur and self.route == "factorization", out_of_core)  # else K singular: no factor
        if schur and self.route == "dirichlet":
            self.factor_dirichlet(out_of_core)

    def _factor_operator(self, schur: bool, out_of_core: bool) -> None:
        """Factor the KSP's operator (with MUMPS's Schur complement on the trace when ``schur``)."""
        pc = self.ksp.getPC()
        controls = {MUMPS_OUT_OF_CORE: 1} if out_of_core else {}
        try:
            if schur:
                pc.setFactorSetUpSolverType()
                trace = PETSc.IS().createGeneral(self.trace_dofs.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
                _call("MatFactorSetSchurIS", pc.getFactorMatrix().handle, trace.handle)
                trace.destroy()
            else:
                controls[MUMPS_ORDERING_CONTROL] = MUMPS_ORDERING
            with _mumps_defaults(self.ksp, controls):
                self.ksp.setUp()
            if schur:
                # Copy S now: solves factor the stored Schur complement in place.  Factor it once here,
                # otherwise every later solve factors it again.
                factor = pc.getFactorMatrix().handle
                self._schur = _schur_complement(factor, len(self.trace_dofs))
                if not self.floating:  # a floating block's S is singular: K is never solved with
                    _call("MatFactorFactorizeSchurComplement", factor)
        except PETSc.Error as exc:
            failure = petsc_failure(exc, self.ksp.getOptionsPrefix())
            hint = SCHUR_HINT if schur and "(from -" not in failure else ""  # not an option's value
            raise SolverError(f"block {self.name}: solver setup failed: {failure}{hint}") from None
        except SolverError as exc:  # the Schur complement's own C calls
            raise SolverError(f"block {self.name}: solver setup failed: {exc}{SCHUR_HINT}") from None
        self.schur_factored = schur

    def factor_dirichlet(self, out_of_core: bool = False) -> None:
        """Set up the Dirichlet problem: K with the trace dofs held (their rows and columns replaced by
        the identity), KSP prefix ``<name>_dirichlet_``, for :meth:`dirichlet` (the FETI preconditioner);
        ``out_of_core`` as for :meth:`factor`.  Once: a block set up already keeps its factorization."""
        if self._dirichlet is not None:
            return
        self._dirichlet_matrix = self.matrix.duplicate(copy=True)
        rows = (self.trace_rows + self.system.first).astype(PETSc.IntType)
        self._dirichlet_matrix.zeroRowsColumns(rows, diag=1.0)
        self._dirichlet_matrix.setOption(PETSc.Mat.Option.SPD, True)
        ksp = PETSc.KSP().create(comm=self.matrix.getComm())
        ksp.setOptionsPrefix(f"{self.name}_dirichlet_")
        ksp.setOperators(self._dirichlet_matrix)
        ksp.setType(PETSc.KSP.Type.PREONLY)
        ksp.getPC().setType(PETSc.PC.Type.CHOLESKY)
        ksp.getPC().setFactorSolverType(self.ksp.getPC().getFactorSolverType())
        self._dirichlet = ksp  # destroyed with the block, whatever happens below
        try:
            ksp.setFromOptions()
            with _mumps_defaults(ksp, {MUMPS_ORDERING_CONTROL: MUMPS_ORDERING,
                                       **({MUMPS_OUT_OF_CORE: 1} if out_of_core else {})}):
                ksp.setUp()
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: Dirichlet problem setup failed: "
                              f"{petsc_failure(exc, ksp.getOptionsPrefix())}") from None
        self._work = self.matrix.createVecLeft()

    def dirichlet(self, trace: np.ndarray) -> np.ndarray | None:
        """S t on the leader: the trace forces that hold the trace displacements ``t`` (given on every
        rank of the block) with no load inside, by one Dirichlet solve and two products with K."""
        return self._gather_trace(self._held_forces(trace))

    def _held_forces(self, trace: np.ndarray) -> np.ndarray:
        """This rank's rows of :meth:`dirichlet`'s trace forces."""
        held = self._work
        values = held.getArray()
        values[:] = 0.0
        values[self.trace_rows] = trace[self.trace_positions]
        self.matrix.mult(held, self.rhs)  # K t (t extended by zero)
        b = self.rhs.getArray()
        b *= -1.0
        b[self.trace_rows] = trace[self.trace_positions]
        try:
            self._dirichlet.solve(self.rhs, self.x)  # x = (−K_II⁻¹ K_IΣ t, t)
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: Dirichlet solve failed (PETSc error {exc.ierr})") from None
        self.matrix.mult(self.x, held)
        return held.getArray(readonly=True)[self.trace_rows] * self.scale

    def trace_diagonal(self) -> np.ndarray | None:
        """The diagonal of K at the trace dofs, on the leader (the stiffness scaling of the preconditioner)."""
        return self._gather_trace(self.matrix.getDiagonal().getArray(readonly=True)[self.trace_rows] * self.scale)

    def held_bytes(self, factored: bool = True) -> dict[str, float]:
        """What the block holds, by kind of :data:`ddsolve.parallel.phases.HELD`: its matrices (with the
        Dirichlet copy), its factors (MUMPS's count, once ``factored``), the Schur complement kept from the
        factorization."""
        copies = 2 if self._dirichlet_matrix is not None else 1
        return {"matrices": copies * self.matrix_bytes, "factors": self.factor_megabytes() * 2 ** 20 if factored else 0.0,
                "schur complements": self._schur.nbytes if self._schur is not None else 0}

    def factor_megabytes(self) -> float:
        """Memory MUMPS reports for this rank's part of the factorization (INFO(16), MB); 0 for other solvers."""
        pc = self.ksp.getPC()
        if not self.is_direct() or pc.getFactorSolverType() != "mumps" or _petsc_c() is None:
            return 0.0
        value = _petsc_int()
        _call("MatMumpsGetInfo", pc.getFactorMatrix().handle, _petsc_int(16), ctypes.byref(value))
        return float(value.value)

    def out_of_core(self) -> bool:
        """Whether MUMPS keeps this rank's factors on disk (ICNTL(22) as the factorization used it)."""
        pc = self.ksp.getPC()
        if not self.is_direct() or pc.getFactorSolverType() != "mumps" or _petsc_c() is None:
            return False
        value = _petsc_int()
        _call("MatMumpsGetIcntl", pc.getFactorMatrix().handle, _petsc_int(MUMPS_OUT_OF_CORE), ctypes.byref(value))
        return bool(value.value)

    def solve(self, load: np.ndarray, body: bool) -> np.ndarray:
        """This rank's rows of x = K⁻¹(rhs·[body] + E load) (a read-only view valid until the next solve).

        ``load`` is the whole trace load, on every rank of the block.
        """
        b = self.rhs.getArray()
        b[:] = self.system.rhs if body else 0.0
        b[self.trace_rows] += load[self.trace_positions]
        self._remember_loads(body, load)
        b[self._fixed_rows] = 0.0  # a floating block's fixed dofs (none otherwise): K⁺ b, see make_floating
        b /= self.scale
        try:
            self.ksp.solve(self.rhs, self.x)
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: solve failed: "
                              f"{petsc_failure(exc, self.ksp.getOptionsPrefix())}") from None
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise SolverError(f"block {self.name}: {self.ksp.getType()} solve did not converge "
                              f"({_reason_name(reason)}); see the -{self.ksp.getOptionsPrefix()}ksp_* and "
                              f"-{self.ksp.getOptionsPrefix()}pc_* options{SCHUR_HINT * self.schur_factored}")
        return self.x.getArray(readonly=True)

    def solve_many(self, loads: np.ndarray) -> np.ndarray | None:
        """The traces of K⁻¹ E L (K⁺ for a floating block) for the trace loads ``loads`` ``(2k, m)`` (on every rank
        of the block), ``(2k, m)`` on the leader: one multi-column solve where the block is factored (a block of
        right-hand sides costs a few times one, not m times), m solves otherwise."""
        if not self.is_direct():
            return self._gather_trace(np.column_stack([self.solve(column, body=False)[self.trace_rows].copy()
                                                       for column in loads.T]))
        local, n = len(self.system.rhs), self.system.size
        B = PETSc.Mat().createDense(((local, n), (None, loads.shape[1])), comm=self.matrix.getComm())
        B.setUp()
        values = B.getDenseArray()
        values[self.trace_rows] = loads[self.trace_positions] / self.scale
        values[self._fixed_rows] = 0.0  # K⁺, as in solve
        B.assemble()
        X = _dense_like(B)
        try:
            self.ksp.getPC().getFactorMatrix().matSolve(B, X)
            traces = X.getDenseArray()[self.trace_rows].copy()
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: multi-column solve failed: "
                              f"{petsc_failure(exc, self.ksp.getOptionsPrefix())}") from None
        finally:
            B.destroy()
            X.destroy()
        return self._gather_trace(traces)

    def _remember_loads(self, body: bool, load: np.ndarray) -> None:
        """Keep the sizes of the two parts of b = f·[body] + E load for :meth:`residual`."""
        self._load_sizes = (float(np.abs(self.system.rhs).max(initial=0.0)) if body else 0.0,
                            float(np.abs(load).max(initial=0.0)))

    def residual(self) -> float:
        """The last solve's relative residual ‖K x − b‖∞ / (‖K‖∞ ‖x‖∞ + ‖f‖∞ + ‖E load‖∞), b = f + E load
        (a backward error: round-off for a direct solve; each part of b on its own, as where the interface
        loads cancel the body loads of a structure that does not move, b itself is round-off; collective over
        the block)."""
        r = self.matrix.createVecLeft()
        self.matrix.mult(self.x, r)
        r.axpy(-1.0, self.rhs)
        norm = PETSc.NormType.INFINITY
        body, load = self._load_sizes
        if self.mpi.size > 1:
            from mpi4py import MPI

            body = self.mpi.allreduce(body, op=MPI.MAX)
        size = self.matrix.norm(norm) * self.x.norm(norm) + (body + load) / self.scale
        value = r.norm(norm)
        r.destroy()
        return value / size if value > 0.0 else 0.0

    def largest_displacement(self, x: np.ndarray) -> float:
        """max nodal |x| over the block (``x``: this rank's rows, whole nodes; collective)."""
        size = self.system.block_size
        local = float(functools.reduce(np.hypot, (x[c::size] for c in range(size))).max(initial=0.0))
        if self.mpi.size == 1:
            return local
        from mpi4py import MPI

        return self.mpi.allreduce(local, op=MPI.MAX)

    def trace(self, x: np.ndarray) -> np.ndarray | None:
        """The trace of the solution whose local rows are ``x``, on the leader."""
        return self._gather_trace(x[self.trace_rows])

    def energies(self) -> np.ndarray | None:
        """(xᵀ b, xᵀ f − c) of the last solve, on the leader: the energy xᵀ K x and the work of the body
        loads f (the traction loads, whatever the interface loads were) less the system's energy offset c
        (prescribed values, thermal load), so that ½ xᵀ K x − (xᵀ f − c) is the block's share of Π."""
        x = self.x.getArray(readonly=True)
        local = np.array([np.dot(x, self.rhs.getArray(readonly=True)) * self.scale,
                          np.dot(x, self.system.rhs) - self.system.energy_offset])
        return self.mpi.reduce(local, root=0) if self.mpi.size > 1 else local

    def gather(self, x: np.ndarray) -> np.ndarray | None:
        """The whole solution (rows in order) on the leader."""
        counts = self.mpi.gather(len(x), root=0)
        out = np.empty(self.system.size) if self.is_leader else None
        self.mpi.Gatherv(np.ascontiguousarray(x), (out, counts) if self.is_leader else None, root=0)
        return out

    def values_at(self, dofs: np.ndarray) -> np.ndarray:
        """The last solution at the block's global ``dofs`` (its rows here and any others; collective over the
        block), by one PETSc scatter."""
        if self.mpi.size == 1:
            return self.x.getArray(readonly=True)[dofs]
        index = PETSc.IS().createGeneral(np.asarray(dofs, dtype=PETSc.IntType), comm=PETSc.COMM_SELF)
        target = PETSc.Vec().createSeq(len(dofs), comm=PETSc.COMM_SELF)
        scatter = PETSc.Scatter().create(self.x, index, target, None)
        try:
            scatter.scatter(self.x, target, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
            return target.getArray().copy()
        finally:
            for obj in (scatter, target, index):
                obj.destroy()

    def _gather_trace(self, values: np.ndarray) -> np.ndarray | None:
        """Trace rows owned here (``(owned,)`` or ``(owned, c)``) -> all of them in trace order, on the leader."""
        if self.mpi.size == 1:
            out = np.empty_like(values)
            out[self.trace_positions] = values
            return out
        width = 1 if values.ndim == 1 else values.shape[1]
        gathered = np.empty(len(self.trace_dofs) * width) if self.is_leader else None
        counts = [c * width for c in self._trace_counts] if self.is_leader else None
        self.mpi.Gatherv(np.ascontiguousarray(values).ravel(), (gathered, counts) if self.is_leader else None, root=0)
        if not self.is_leader:
            return None
        out = np.empty((len(self.trace_dofs), width))
        out[self._trace_order] = gathered.reshape(-1, width)
        return out if values.ndim == 2 else out[:, 0]

    def schur_complement(self) -> np.ndarray | None:
        """Dense (2k, 2k) Schur complement of K on the trace dofs, S = (E K⁻¹ Eᵀ)⁻¹, on the leader.

        With MUMPS on one rank it comes from the factorization, no solve needed.  MUMPS fills one
        triangle of a symmetric Schur complement (which one may depend on the version) and PETSc's
        dense matrix starts zeroed, so the triangle is the one with nonzeros off the diagonal; a
        matrix filled on both sides must be symmetric.  Otherwise (distributed blocks, other
        packages, or a stored matrix that fits none of these) by the route :meth:`factor` chose: from the
        Dirichlet factorization (:meth:`interface_stiffness`), or the inverse of the flexibility.
        """
        if self._schur is not None:  # handed over once, filled in place (S is large: (2k)² doubles)
            stored, self._schur = self._schur, None
            stored *= self.scale  # MUMPS's is that of K/s
            above = np.triu_indices(len(stored), 1)
            lower, upper = np.abs(stored.T[above]).max(initial=0.0), np.abs(stored[above]).max(initial=0.0)
            if upper == 0.0:
                stored[above] = stored.T[above]
                return stored
            if lower == 0.0:
                stored.T[above] = stored[above]
                return stored
            if np.abs(stored - stored.T).max() <= 1e-12 * np.abs(stored).max():
                return 0.5 * (stored + stored.T)
        if self.route == "dirichlet" or self.floating:
            return self.interface_stiffness()
        flexibility = self.inverse_entries() if self.route == "inverse" else self.flexibility()
        return np.linalg.inv(flexibility) if self.is_leader else None

    def inverse_entries(self) -> np.ndarray:
        """Dense (2k, 2k) interface flexibility E K⁻¹ Eᵀ of a whole block factored by MUMPS, from
        MUMPS's computation of selected entries of the inverse (ICNTL(30): sparse right-hand sides,
        pruned elimination tree), in one call."""
        trace = self.trace_dofs.astype(PETSc.IntType)
        k, n = len(trace), self.system.size
        counts = np.zeros(n, dtype=PETSc.IntType)
        counts[trace] = k
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
        order = np.argsort(trace)
        values = np.zeros(k * k)
        requested = PETSc.Mat().createAIJWithArrays((n, n), (indptr, np.tile(trace[order], k), values),
                                                    comm=PETSc.COMM_SELF)
        wrapped = PETSc.Mat().createTranspose(requested)
        factor = self.ksp.getPC().getFactorMatrix()
        try:
            _call("MatMumpsGetInverse", factor.handle, wrapped.handle)
        finally:
            factor.setMumpsIcntl(30, 0)  # later solves are ordinary ones
            wrapped.destroy()
        rows = requested.getValuesCSR()[2].reshape(k, k) / self.scale  # rows and columns in sorted order
        requested.destroy()
        position = np.empty(k, dtype=np.int64)
        position[order] = np.arange(k)
        out = rows[np.ix_(position, position)]
        return 0.5 * (out + out.T)

    def flexibility(self) -> np.ndarray | None:
        """Dense (2k, 2k) interface flexibility E K⁻¹ Eᵀ on the leader, symmetrized: the traces of unit trace loads,
        :data:`_CHUNK` columns per :meth:`solve_many`."""
        k = len(self.trace_dofs)
        chunks = []
        for start in range(0, k, _CHUNK):
            width = min(_CHUNK, k - start)
            units = np.zeros((k, width))
            units[start + np.arange(width), np.arange(width)] = 1.0
            chunks.append(self.solve_many(units))
        if not self.is_leader:
            return None
        out = np.hstack(chunks)
        return 0.5 * (out + out.T)

    def _trace_columns(self, ksp: PETSc.KSP, columns_of: Callable, one_column: Callable[[np.ndarray], np.ndarray]
                       ) -> np.ndarray | None:
        """A dense (2k, 2k) matrix on the leader (:meth:`interface_stiffness`'s), symmetrized, whose columns for unit
        traces are computed
        _CHUNK at a time from a dense matrix of unit columns at the trace rows by ``columns_of(units,
        solve)`` (``solve(B, X)``: X = (factored operator of ``ksp``)⁻¹ B) when ``ksp`` is a direct solver,
        one by one by ``one_column(unit trace)`` (this rank's trace rows) otherwise."""
        k = len(self.trace_dofs)
        out = np.empty((k, k)) if self.is_leader else None
        local, n = len(self.system.rhs), self.system.size
        direct = _is_direct(ksp)
        for start in range(0, k, _CHUNK):
            columns = np.arange(start, min(start + _CHUNK, k))
            if direct:
                units = PETSc.Mat().createDense(((local, n), (None, len(columns))), comm=self.matrix.getComm())
                units.setUp()
                chosen = (self.trace_positions >= columns[0]) & (self.trace_positions <= columns[-1])
                units.getDenseArray()[self.trace_rows[chosen], self.trace_positions[chosen] - columns[0]] = 1.0
                units.assemble()
                block = columns_of(units, ksp.getPC().getFactorMatrix().matSolve)
                units.destroy()
            else:
                unit = np.zeros(k)
                block = np.empty((len(self.trace_rows), len(columns)))
                for j, column in enumerate(columns):
                    unit[column] = 1.0
                    block[:, j] = one_column(unit)
                    unit[column] = 0.0
            gathered = self._gather_trace(block)
            if self.is_leader:
                out[:, columns] = gathered
        return 0.5 * (out + out.T) if self.is_leader else None

    def destroy(self) -> None:
        for obj in (self.ksp, self.matrix, self.rhs, self.x, self._dirichlet, self._dirichlet_matrix, self._work,
                    self._fixed_matrix):
            if obj is not None:
                obj.destroy()

    # --- floating blocks: K singular, its kernel the rigid motions its supports leave -----------------
    @property
    def floating(self) -> bool:
        return self.kernel is not None

    def make_floating(self, kernel: np.ndarray, fixed: np.ndarray | None = None) -> None:
        """Mark the block floating with its kernel ``(m, local rows)``.  With ``fixed`` (m global dofs where
        the kernel is independent, off the trace), the KSP gets K with those dofs held at zero, so that
        :meth:`solve` applies a generalized inverse K⁺ (FETI's); call before :meth:`factor`."""
        self.kernel = np.array(kernel, dtype=np.float64)
        if fixed is None:
            return
        first = self.system.first
        mine = (fixed >= first) & (fixed < first + len(self.system.rhs))
        self._fixed_rows = np.asarray(fixed[mine], dtype=np.int64) - first
        self._fixed_matrix = self.matrix.duplicate(copy=True)
        self._fixed_matrix.zeroRowsColumns(np.asarray(fixed, dtype=PETSc.IntType)[mine], diag=1.0)
        self._fixed_matrix.setOption(PETSc.Mat.Option.SPD, True)
        self.ksp.setOperators(self._fixed_matrix)

    def interface_stiffness(self) -> np.ndarray | None:
        """S = K_ΣΣ − K_ΣI K_II⁻¹ K_IΣ on the leader from the Dirichlet factorization (only K_II is inverted:
        a floating block's S, singular on its kernel): multi-column solves X = (−K_II⁻¹ K_IΣ T, T) for unit
        traces T, then the trace rows of K X."""
        def columns_of(units: PETSc.Mat, solve: Callable[[PETSc.Mat, PETSc.Mat], None]) -> np.ndarray:
            held = self.matrix.matMult(units)  # K T
            values = held.getDenseArray()
            values *= -1.0
            values[self.trace_rows, :] = units.getDenseArray()[self.trace_rows, :]
            X = _dense_like(units)
            solve(held, X)
            forces = self.matrix.matMult(X)
            out = forces.getDenseArray()[self.trace_rows, :] * self.scale
            for mat in (held, X, forces):
                mat.destroy()
            return out

        return self._trace_columns(self._dirichlet, columns_of, self._held_forces)

    def _held_solve(self, trace: np.ndarray) -> None:
        """self.x = (K_II⁻¹(f_I − K_IΣ t), t) for trace displacements ``t`` (on every rank of the block)."""
        held = self._work
        values = held.getArray()
        values[:] = 0.0
        values[self.trace_rows] = trace[self.trace_positions]
        self.matrix.mult(held, self.rhs)  # (K/s) t
        b = self.rhs.getArray()
        b[:] = self.system.rhs / self.scale - b
        b[self.trace_rows] = trace[self.trace_positions]
        try:
            self._dirichlet.solve(self.rhs, self.x)
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: Dirichlet solve failed (PETSc error {exc.ierr})") from None

    def condensed_load(self) -> np.ndarray | None:
        """g = f_Σ − K_ΣI K_II⁻¹ f_I on the leader (= S t⁰ for an invertible block): one Dirichlet solve."""
        self._held_solve(np.zeros(len(self.trace_dofs)))
        forces = self._work
        self.matrix.mult(self.x, forces)
        g = (self.system.rhs[self.trace_rows] - forces.getArray(readonly=True)[self.trace_rows] * self.scale)
        return self._gather_trace(g)

    def expand(self, trace: np.ndarray, load: np.ndarray) -> np.ndarray:
        """This rank's rows of the solution with trace displacements ``trace`` and no other interface
        condition inside, x = (K_II⁻¹(f_I − K_IΣ t), t); the right-hand side kept is f + E load, so that
        :meth:`residual` measures the equilibrium with the interface loads ``load`` (both on every rank).
        A floating block without a Dirichlet factorization (feti's K⁺ alone) takes x = K⁺(f + E load) + R α
        instead, α fitting its trace to ``trace`` (least squares: TFETI's amplitudes, where ``trace`` is
        :meth:`~ddsolve.dd.feti.Coarse.held`'s)."""
        if self._dirichlet is None and self.kernel is not None:
            return self._kernel_fit(trace, load)
        self._held_solve(trace)
        b = self.rhs.getArray()
        b[:] = self.system.rhs
        b[self.trace_rows] += load[self.trace_positions]
        self._remember_loads(True, load)
        b /= self.scale
        return self.x.getArray(readonly=True)

    def _kernel_fit(self, trace: np.ndarray, load: np.ndarray) -> np.ndarray:
        """x = K⁺(f + E load) + R α with α the least-squares fit of its trace to ``trace`` (see :meth:`expand`)."""
        x = self.solve(load, body=True).copy()
        b = self.rhs.getArray()
        b[:] = self.system.rhs  # the whole right-hand side, fixed rows included, for residual
        b[self.trace_rows] += load[self.trace_positions]
        b /= self.scale
        at_trace = self.kernel[:, self.trace_rows]
        gap = trace[self.trace_positions] - x[self.trace_rows]
        normal = np.column_stack([at_trace @ at_trace.T, at_trace @ gap])  # RᵀR and Rᵀ gap at this rank's trace
        if self.mpi.size > 1:
            from mpi4py import MPI

            normal = self.mpi.allreduce(normal, op=MPI.SUM)
        x += self.kernel.T @ np.linalg.solve(normal[:, :-1], normal[:, -1])
        self.x.getArray()[:] = x
        return self.x.getArray(readonly=True)

    def kernel_work(self) -> np.ndarray | None:
        """Rᵀ f on the leader: the work of the body loads in the block's rigid motions ``(m,)``."""
        local = self.kernel @ self.system.rhs
        return self.mpi.reduce(local, root=0) if self.mpi.size > 1 else local


def diagonal_scale(system: BlockSystem, comm) -> float:
    """The power of two nearest the largest |diagonal entry| of the block (over all its ranks; 1 if
    there is none)."""
    rows = np.repeat(np.arange(len(system.rhs)), np.diff(system.indptr)) + system.first
    diagonal = np.abs(system.data[system.indices == rows])
    largest = float(diagonal.max(initial=0.0))
    if comm.size > 1:
        from mpi4py import MPI

        largest = comm.allreduce(largest, op=MPI.MAX)
    if not (math.isfinite(largest) and largest > 0.0):
        return 1.0
    return math.ldexp(1.0, math.frexp(largest)[1] - 1)


#: What a block factored with its Schur complement on its trace (method schur) failing most likely means.
SCHUR_HINT = ("; with its Schur complement on the trace (solver.method = schur), which fails on a block with few "
              "or no nodes off its interfaces (a region thinner than mesh.size): use solver.method = feti or mprgp")


def petsc_failure(exc: PETSc.Error, prefix: str | None) -> str:
    """One line for a PETSc error: PETSc's most specific message and the options (under ``prefix``)
    whose values it names, e.g. «Unable to find requested PC type nonsense (from -u_minus_pc_type
    nonsense)»."""
    messages = [line.split("] ", 1)[1].strip() for line in str(exc).splitlines()
                if line.startswith("[") and "] " in line]
    messages = [m for m in messages if m and not re.match(r"[\w:]+\(\) at |See |Petsc |Configure ", m)]
    detail = messages[-1] if messages else f"error code {exc.ierr}"
    options = PETSc.Options().getAll()
    named = [f"-{key} {value}" for key, value in sorted(options.items())
             if (not prefix or key.startswith(prefix)) and value and re.search(rf"\b{re.escape(str(value))}\b", detail)]
    return detail + (f" (from {', '.join(named)})" if named else "")


def _reason_name(reason: int) -> str:
    """A KSP converged reason as PETSc names it (e.g. DIVERGED_PC_FAILED), with its number."""
    names = {value: name for name, value in vars(PETSc.KSP.ConvergedReason).items()
             if isinstance(value, int) and not name.startswith("_")}
    return f"{names.get(reason, 'reason')} {reason}"


# --- PETSc C calls that petsc4py does not wrap (MatFactorSetSchurIS and friends) --------------
def _petsc_int(value: int = 0):
    """A ctypes PetscInt (a new one: C calls write into it)."""
    return (ctypes.c_int64 if np.dtype(PETSc.IntType).itemsize == 8 else ctypes.c_int32)(value)


@functools.lru_cache(maxsize=None)
def _petsc_c():
    """The loaded PETSc shared library, or None when it cannot be found (then no Schur shortcut)."""
    candidates = []
    try:
        with open("/proc/self/maps") as maps:
            candidates = [line.split()[-1] for line in maps if "libpetsc" in line and ".so" in line]
    except OSError:
        pass
    config = __import__("petsc4py").get_config()
    libdir = os.path.join(config["PETSC_DIR"], config.get("PETSC_ARCH") or "", "lib")
    candidates += [os.path.join(libdir, name) for name in sorted(os.listdir(libdir))
                   if name.startswith("libpetsc")] if os.path.isdir(libdir) else []
    if np.dtype(PETSc.ScalarType) != np.float64:
        return None
    for path in candidates:
        try:
            lib = ctypes.CDLL(path)
            lib.MatFactorSetSchurIS  # noqa: B018 - probe the symbol
            return lib
        except (OSError, AttributeError):
            continue
    return None


#: MUMPS's ordering for plain factorizations: AMF.  On these 2D elasticity blocks its analysis is
#: several times faster than METIS's or PORD's (what MUMPS picks by itself) for the same fill: the
#: whole factorization takes half the time (``./run bench factor``).  With a Schur complement
#: MUMPS orders by AMD whatever is asked.  ``-<block>_mat_mumps_icntl_7`` overrides it.
MUMPS_ORDERING_CONTROL, MUMPS_ORDERING = 7, 2


#: MUMPS's out-of-core control: 1 keeps the factors in files (in ``MUMPS_OOC_TMPDIR``, else the system's
#: temporary directory) and reads them back at every solve, so a rank holds about a third of the memory.
MUMPS_OUT_OF_CORE = 22


@contextlib.contextmanager
def _mumps_defaults(ksp: PETSc.KSP, controls: dict[int, int]):
    """While the block is factored, give MUMPS (if it factors this KSP's matrix) the ICNTL ``controls``
    unless the options say otherwise (MUMPS reads its controls from the options when it starts, at the
    factorization); they are removed from PETSc's database again afterwards."""
    pc = ksp.getPC()
    options, prefix = PETSc.Options(), f"{ksp.getOptionsPrefix() or ''}mat_mumps_icntl_"
    mumps = (ksp.getType() == PETSc.KSP.Type.PREONLY and pc.getType() in _FACTOR_TYPES
             and pc.getFactorSolverType() == "mumps")
    ours = [f"{prefix}{control}" for control in controls if mumps and not options.hasName(f"{prefix}{control}")]
    for key in ours:
        options[key] = controls[int(key[len(prefix):])]
    try:
        yield
    finally:
        for key in ours:
            options.delValue(key)


#: Options PETSc itself reads only when it finalizes.
_READ_AT_FINALIZE = ("options_left",)


#: The options prefixes of the blocks this process has made, in order (:func:`made_prefixes`).
_MADE_PREFIXES: list[str] = []


def made_prefixes() -> list[str]:
    """The options prefixes (``NAME_``) of the blocks this process has made so far: what the structure solved
    takes, whatever its blocks (halves, slabs, regions or a file's volumes)."""
    return list(_MADE_PREFIXES)


def unused_options() -> list[str] | None:
    """``-name value`` of every PETSc option set (command line, PETSC_OPTIONS, files) that nothing in
    this process has read so far; None when this PETSc cannot tell."""
    lib = _petsc_c()
    if lib is None or not hasattr(lib, "PetscOptionsLeftGet"):
        return None
    count, names, values = _petsc_int(), ctypes.POINTER(ctypes.c_char_p)(), ctypes.POINTER(ctypes.c_char_p)()
    if lib.PetscOptionsLeftGet(None, ctypes.byref(count), ctypes.byref(names), ctypes.byref(values)) != 0:
        return None
    left = []
    for i in range(count.value):
        name = names[i].decode(errors="replace")
        value = values[i].decode(errors="replace") if values[i] else ""
        if name not in _READ_AT_FINALIZE:
            left.append(f"-{name} {value}".strip())
    lib.PetscOptionsLeftRestore(None, ctypes.byref(count), ctypes.byref(names), ctypes.byref(values))
    return left


def _call(function: str, *args) -> None:
    code = getattr(_petsc_c(), function)(*(ctypes.c_void_p(a) if isinstance(a, int) else a for a in args))
    if code != 0:
        raise SolverError(f"PETSc {function} failed with error {code}")


def _is_direct(ksp: PETSc.KSP) -> bool:
    """Whether ``ksp`` applies a factorization (no Krylov iterations)."""
    return ksp.getType() == PETSc.KSP.Type.PREONLY and ksp.getPC().getType() in _FACTOR_TYPES


def _dense_like(B: PETSc.Mat) -> PETSc.Mat:
    """An assembled dense matrix with the layout of ``B`` (the solution of a multi-column solve)."""
    X = PETSc.Mat().createDense(B.getSizes(), comm=B.getComm())
    X.setUp()
    X.assemble()
    return X


def _schur_complement(factor_handle: int, size: int) -> np.ndarray:
    """Copy the dense Schur complement held by a MUMPS factor, as stored (see ``schur_complement``)."""
    lib = _petsc_c()
    schur = ctypes.c_void_p()
    status = ctypes.c_int()
    _call("MatFactorGetSchurComplement", factor_handle, ctypes.byref(schur), ctypes.byref(status))
    lda = _petsc_int()
    values = ctypes.POINTER(ctypes.c_double)()
    _call("MatDenseGetLDA", schur.value, ctypes.byref(lda))
    _call("MatDenseGetArrayRead", schur.value, ctypes.byref(values))
    out = np.ctypeslib.as_array(values, shape=(size, lda.value))[:, :size].T.copy()  # column-major
    _call("MatDenseRestoreArrayRead", schur.value, ctypes.byref(values))
    lib.MatFactorRestoreSchurComplement(ctypes.c_void_p(factor_handle), ctypes.byref(schur), status)
    return out
