"""One elasticity block as a PETSc matrix and KSP, factored once and solved many times.

Each block's KSP has the options prefix ``<block name>_`` (``u_minus_``, ``u_plus_``, ``v_minus_``,
``v_plus_``).  Code defaults (preonly + Cholesky, MUMPS when PETSc has it) are set first and
``setFromOptions`` last, so ``-u_minus_ksp_type cg -u_minus_pc_type gamg`` work from the command line.
"""
from __future__ import annotations

import ctypes
import functools
import os

import numpy as np
from petsc4py import PETSc

from .assembly import BlockSystem
from .errors import SolverError

_FACTOR_TYPES = ("cholesky", "lu")
_CHUNK = 64  # right-hand sides per multi-column solve when the flexibility is built by solves


def default_factor_package(preferred: str = "mumps") -> str:
    """``preferred`` if this PETSc has it, else PETSc's own factorization."""
    return preferred if preferred == "petsc" or PETSc.Sys.hasExternalPackage(preferred) else "petsc"


class Block:
    """K x = rhs + E·load for one block, where E puts a trace load onto the Σ degrees of freedom.

    ``factor_package`` is the default Cholesky package (``mumps`` or ``petsc``); the options
    ``-<name>_pc_factor_mat_solver_type`` and friends override it.
    """

    def __init__(self, system: BlockSystem, comm: PETSc.Comm = PETSc.COMM_SELF, factor_package: str = "mumps"):
        self.system = system
        self.name = system.name
        n = system.size
        csr = tuple(a.astype(PETSc.IntType) for a in (system.indptr, system.indices)) + (system.data,)
        self.matrix = PETSc.Mat().createAIJ(size=(n, n), bsize=system.block_size, csr=csr, comm=comm)
        self.matrix.setOption(PETSc.Mat.Option.SPD, True)
        self.ksp = PETSc.KSP().create(comm=comm)
        self.ksp.setOptionsPrefix(f"{self.name}_")
        self.ksp.setOperators(self.matrix)
        self.ksp.setType(PETSc.KSP.Type.PREONLY)
        pc = self.ksp.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        pc.setFactorSolverType(default_factor_package(factor_package))
        self.ksp.setFromOptions()
        self.rhs, self.x = self.matrix.createVecLeft(), self.matrix.createVecRight()
        self._schur: np.ndarray | None = None  # as stored by MUMPS (one triangle valid)

    @property
    def trace_dofs(self) -> np.ndarray:
        return self.system.trace_dofs

    def is_direct(self) -> bool:
        return self.ksp.getType() == PETSc.KSP.Type.PREONLY and self.ksp.getPC().getType() in _FACTOR_TYPES

    def factor(self, schur: bool = False) -> None:
        """Set up the solver (factorization for direct solvers).

        With ``schur`` and MUMPS, the Schur complement on the trace dofs is requested from the
        factorization, so :meth:`schur_complement` costs no extra solves.
        """
        pc = self.ksp.getPC()
        schur = schur and self.is_direct() and pc.getFactorSolverType() == "mumps" and _petsc_c() is not None
        try:
            if schur:
                pc.setFactorSetUpSolverType()
                trace = PETSc.IS().createGeneral(self.trace_dofs.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
                _call("MatFactorSetSchurIS", pc.getFactorMatrix().handle, trace.handle)
                trace.destroy()
            self.ksp.setUp()
            if schur:
                # Copy S now: solves factor the stored Schur complement in place.  Factor it once here,
                # otherwise every later solve factors it again.
                factor = pc.getFactorMatrix().handle
                self._schur = _schur_complement(factor, len(self.trace_dofs))
                _call("MatFactorFactorizeSchurComplement", factor)
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: solver setup failed (PETSc error {exc.ierr}); "
                              "is the block clamped?") from None

    def solve(self, load: np.ndarray, body: bool) -> np.ndarray:
        """x = K⁻¹(rhs·[body] + E load); returns a read-only view valid until the next solve."""
        b = self.rhs.getArray()
        b[:] = self.system.rhs if body else 0.0
        b[self.trace_dofs] += load
        try:
            self.ksp.solve(self.rhs, self.x)
        except PETSc.Error as exc:
            raise SolverError(f"block {self.name}: solve failed (PETSc error {exc.ierr})") from None
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise SolverError(f"block {self.name}: KSP did not converge (reason {reason})")
        return self.x.getArray(readonly=True)

    def schur_complement(self) -> np.ndarray:
        """Dense (2k, 2k) Schur complement of K on the trace dofs: S = (E K⁻¹ Eᵀ)⁻¹.

        With MUMPS it comes from the factorization.  MUMPS fills only one triangle of a symmetric
        Schur complement; which one may depend on the version, so one solve with a random trace
        load decides (S t must give back the load) and also validates the matrix.
        """
        k = len(self.trace_dofs)
        if self._schur is not None:
            stored = self._schur
            load = np.random.default_rng(7).standard_normal(k)
            trace = self.solve(load, body=False)[self.trace_dofs]
            candidates = [np.tril(stored) + np.tril(stored, -1).T, np.triu(stored) + np.triu(stored, 1).T]
            residuals = [np.linalg.norm(S @ trace - load) for S in candidates]
            best = int(np.argmin(residuals))
            if residuals[best] <= 1e-8 * np.linalg.norm(load):
                return candidates[best]
        return np.linalg.inv(self.flexibility())

    def flexibility(self) -> np.ndarray:
        """Dense (2k, 2k) interface flexibility E K⁻¹ Eᵀ, by multi-column solves with the factor."""
        dofs = self.trace_dofs
        k = len(dofs)
        out = np.empty((k, k))
        if self.is_direct():
            factor = self.ksp.getPC().getFactorMatrix()
            n = self.system.size
            for start in range(0, k, _CHUNK):
                cols = np.arange(start, min(start + _CHUNK, k))
                B = PETSc.Mat().createDense((n, len(cols)), comm=PETSc.COMM_SELF)
                B.setUp()
                B.getDenseArray()[dofs[cols], np.arange(len(cols))] = 1.0
                B.assemble()
                X = PETSc.Mat().createDense((n, len(cols)), comm=PETSc.COMM_SELF)
                X.setUp()
                factor.matSolve(B, X)
                out[:, cols] = X.getDenseArray()[dofs, :]
                B.destroy()
                X.destroy()
        else:
            unit = np.zeros(k)
            for j in range(k):
                unit[j] = 1.0
                out[:, j] = self.solve(unit, body=False)[dofs]
                unit[j] = 0.0
        return 0.5 * (out + out.T)

    def destroy(self) -> None:
        for obj in (self.ksp, self.matrix, self.rhs, self.x):
            obj.destroy()


# --- PETSc C calls that petsc4py does not wrap (MatFactorSetSchurIS and friends) --------------
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


def _call(function: str, *args) -> None:
    code = getattr(_petsc_c(), function)(*(ctypes.c_void_p(a) if isinstance(a, int) else a for a in args))
    if code != 0:
        raise SolverError(f"PETSc {function} failed with error {code}")


def _schur_complement(factor_handle: int, size: int) -> np.ndarray:
    """Copy the dense Schur complement held by a MUMPS factor, as stored (see ``schur_complement``)."""
    lib = _petsc_c()
    schur = ctypes.c_void_p()
    status = ctypes.c_int()
    _call("MatFactorGetSchurComplement", factor_handle, ctypes.byref(schur), ctypes.byref(status))
    integer = ctypes.c_int64 if np.dtype(PETSc.IntType).itemsize == 8 else ctypes.c_int32
    lda = integer()
    values = ctypes.POINTER(ctypes.c_double)()
    _call("MatDenseGetLDA", schur.value, ctypes.byref(lda))
    _call("MatDenseGetArrayRead", schur.value, ctypes.byref(values))
    out = np.ctypeslib.as_array(values, shape=(size, lda.value))[:, :size].T.copy()  # column-major
    _call("MatDenseRestoreArrayRead", schur.value, ctypes.byref(values))
    lib.MatFactorRestoreSchurComplement(ctypes.c_void_p(factor_handle), ctypes.byref(schur), status)
    return out
