"""Hooke's law of a layer in the plane: isotropic, orthotropic with a fibre angle, or a full matrix.

Stresses and strains are in Voigt order (xx, yy, xy) with the engineering shear γxy = 2εxy, so that
σ = D ε.  The plane model decides what the third direction does: ``plane_strain`` (εzz = 0, the
default, σzz = c·ε) or ``plane_stress`` (σzz = 0).  Orthotropic layers are built from the 3-D
orthotropic law in the fibre frame, rotated about z by the fibre angle, then reduced to the plane;
isotropic constants give exactly the isotropic law.  No PETSc, MPI or meshes here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Union

import numpy as np

MODELS = ("plane_strain", "plane_stress")
#: Voigt positions of xx, yy, zz and xy among (xx, yy, zz, yz, xz, xy).
_PLANE, _ZZ = [0, 1, 5], 2


@dataclass(frozen=True)
class Isotropic:
    E: float
    nu: float
    alpha: float = 0.0  # thermal expansion coefficient


@dataclass(frozen=True)
class Orthotropic:
    """Fibre direction 1 at ``angle`` degrees from x, direction 2 in the plane, 3 out of it.

    The out-of-plane constants matter for plane strain only; they default to E3 = E2, ν13 = ν12 and
    ν23 = ν12 (so that isotropic constants give the isotropic law).  The expansion coefficient out of
    the plane is ``alpha2``.
    """

    E1: float
    E2: float
    G12: float
    nu12: float
    angle: float = 0.0
    E3: float | None = None
    nu13: float | None = None
    nu23: float | None = None
    alpha1: float = 0.0  # thermal expansion along the fibres
    alpha2: float = 0.0  # across them, in the plane and out of it
    fibre: tuple[float, float, float] | None = None  # 3-D only: the fibre direction (x, y, z), replacing angle


@dataclass(frozen=True)
class Anisotropic:
    """A full in-plane stiffness D (σ = D ε), used as given; σzz = Dzz·ε for plane strain."""

    D: tuple[tuple[float, float, float], ...]
    Dzz: tuple[float, float, float] = (0.0, 0.0, 0.0)


Material = Union[Isotropic, Orthotropic, Anisotropic]


class MaterialError(ValueError):
    """The constants do not define a positive definite law."""


def elasticity(material, model: str = "plane_strain") -> tuple[np.ndarray, np.ndarray]:
    """(D, c): the in-plane stiffness ``(3, 3)`` and the row giving σzz = c·ε ``(3,)``."""
    if isinstance(material, Anisotropic):
        D = np.array(material.D, dtype=float)
        check_positive_definite(D, "D")
        return D, (np.array(material.Dzz, dtype=float) if model == "plane_strain" else np.zeros(3))
    C = stiffness_3d(material)
    if model == "plane_strain":
        return C[np.ix_(_PLANE, _PLANE)], C[_ZZ, _PLANE]
    S = np.linalg.inv(C)
    return np.linalg.inv(S[np.ix_(_PLANE, _PLANE)]), np.zeros(3)


def out_of_plane_strain(material, model: str = "plane_strain") -> tuple[np.ndarray, float] | None:
    """(e, t) giving the total εzz = e·ε + t ΔT: zeros for plane strain; for plane stress, from σzz = 0 with
    the 3-D law and eigenstrain α ΔT (t = C_z·α / C_zz, so εzz = α_zz ΔT under free expansion); None for a
    full matrix in plane stress (its 3-D law is not known)."""
    if model == "plane_strain":
        return np.zeros(3), 0.0
    if isinstance(material, Anisotropic):
        return None
    C = stiffness_3d(material)
    return -C[_ZZ, _PLANE] / C[_ZZ, _ZZ], float(C[_ZZ] @ expansion(material)) / C[_ZZ, _ZZ]


def thermal_strain(material, model: str = "plane_strain") -> tuple[np.ndarray, float]:
    """(e, s) per unit temperature change: the in-plane eigenstrain ε₀ = e ΔT (Voigt, engineering shear)
    with σ = D (ε − ε₀), and the out-of-plane stress σzz = c·ε − s ΔT.

    The 3-D eigenstrain is α ΔT (α: :func:`expansion`).
    Plane stress: ε₀ is its in-plane part and σzz = 0.  Plane strain (εzz = 0): σ_p = C_pp ε − (C_pp ε₀_p +
    C_pz ε₀_zz), so ε₀ = ε₀_p + C_pp⁻¹ C_pz ε₀_zz ((1 + ν) α ΔT for an isotropic layer), and
    s = C_zp ε₀_p + C_zz ε₀_zz.  A full matrix (``Anisotropic``) takes no expansion.
    """
    if isinstance(material, Anisotropic):
        return np.zeros(3), 0.0
    strain = expansion(material)
    in_plane = strain[_PLANE]
    if model == "plane_stress":
        return in_plane, 0.0
    C = stiffness_3d(material)
    coupling = C[_PLANE, _ZZ]
    return in_plane + np.linalg.solve(C[np.ix_(_PLANE, _PLANE)], coupling) * strain[_ZZ], \
        float(C[_ZZ, _PLANE] @ in_plane + C[_ZZ, _ZZ] * strain[_ZZ])


def expansion(material) -> np.ndarray:
    """The 3-D eigenstrain per unit temperature change ``(6,)`` (Voigt, engineering shears) of an isotropic or
    orthotropic layer: α = diag(α1, α2, α2) in the fibre frame, rotated by the fibre angle."""
    if isinstance(material, Isotropic):
        return np.array([material.alpha, material.alpha, material.alpha, 0.0, 0.0, 0.0])
    cos, sin = math.cos(math.radians(material.angle)), math.sin(math.radians(material.angle))
    a1, a2 = material.alpha1, material.alpha2
    return np.array([a1 * cos ** 2 + a2 * sin ** 2, a1 * sin ** 2 + a2 * cos ** 2, a2, 0.0, 0.0,
                     2.0 * (a1 - a2) * sin * cos])


def same_law(first: Material, second: Material, model: str = "plane_strain", thermal: bool = True) -> bool:
    """Whether two materials have the same plane law under ``model``: equal (D, c), and with ``thermal`` equal
    thermal strains (e, s) too."""
    def law(material: Material) -> tuple[np.ndarray, ...]:
        return (*elasticity(material, model), *(thermal_strain(material, model) if thermal else ()))

    return all(np.array_equal(a, b) for a, b in zip(law(first), law(second)))


def differing(groups: dict[str, Sequence[Material]], model: str = "plane_strain", thermal: bool = True) -> list[str]:
    """The keys of ``groups`` whose materials do not all have the same plane law (:func:`same_law`)."""
    return [key for key, group in groups.items()
            if not all(same_law(group[0], other, model, thermal) for other in group[1:])]


@dataclass(frozen=True)
class Bimaterial:
    """The isotropic pair of an interface crack: shear modulus μ and Kolosov constant κ below and above Σ
    (of the sheets' stiffnesses summed over the layers, :func:`interface_pair`)."""

    lower: tuple[float, float]
    upper: tuple[float, float]


#: Laws this close (relative to the largest entry) are equal, isotropic, or proportional.
LAW_TOLERANCE = 1e-10


def interface_pair(lower: Sequence[np.ndarray], upper: Sequence[np.ndarray]) -> Bimaterial | str:
    """The effective isotropic pair of the layers' in-plane laws D (one per layer) below and above Σ, or why
    there is none.  The layers are tied along Σ; where each layer's pair is the same pair times one factor
    (equal Poisson's ratios in a region), every layer carries the same near-tip field and the structure's is
    that of one sheet of the summed stiffness.  Orthotropic laws, and layers whose pairs are not
    proportional, have no such pair."""
    for D in (*lower, *upper):
        scale = np.abs(D).max()
        if (max(abs(D[0, 2]), abs(D[1, 2]), abs(D[0, 0] - D[1, 1]), abs(2.0 * D[2, 2] - D[0, 0] + D[0, 1]))
                > LAW_TOLERANCE * scale):
            return "a region's material is not isotropic"
    factors = [np.abs(D).max() / np.abs(lower[0]).max() for D in lower]
    for group, first in ((lower, lower[0]), (upper, upper[0])):
        for D, factor in zip(group, factors):
            if np.abs(D - factor * first).max() > LAW_TOLERANCE * np.abs(D).max():
                return "the layers' pairs of materials below and above Σ are not proportional"

    def constants(D: np.ndarray) -> tuple[float, float]:
        shear, lame = float(D[2, 2]), float(D[0, 1])  # κ = (3μ + λ)/(μ + λ): 3 − 4ν, or (3 − ν)/(1 + ν) in plane stress
        return shear, (3.0 * shear + lame) / (shear + lame)

    return Bimaterial(constants(sum(lower)), constants(sum(upper)))


def check_positive_definite(D: np.ndarray, name: str) -> None:
    """Raise MaterialError unless ``D`` is symmetric positive definite (to round-off)."""
    scale = np.abs(D).max(initial=0.0)
    if not np.all(np.isfinite(D)) or scale == 0.0:
        raise MaterialError(f"{name} must be a finite non-zero matrix")
    if np.abs(D - D.T).max() > 1e-12 * scale:
        raise MaterialError(f"{name} is not symmetric")
    smallest = np.linalg.eigvalsh(0.5 * (D + D.T)).min()
    if smallest <= 1e-12 * scale:
        raise MaterialError(f"{name} is not positive definite (smallest eigenvalue {smallest:.3g})")


def stiffness_3d(material) -> np.ndarray:
    """6×6 Voigt stiffness (engineering shears) in the x, y, z frame."""
    if isinstance(material, Isotropic):
        E, nu = material.E, material.nu
        mu, lam = E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
        C = np.zeros((6, 6))
        C[:3, :3] = lam
        C[[0, 1, 2], [0, 1, 2]] += 2.0 * mu
        C[[3, 4, 5], [3, 4, 5]] = mu
        return C
    m = material
    E3 = m.E2 if m.E3 is None else m.E3
    nu13 = m.nu12 if m.nu13 is None else m.nu13
    nu23 = m.nu12 if m.nu23 is None else m.nu23
    S = np.zeros((6, 6))
    S[:3, :3] = [[1.0 / m.E1, -m.nu12 / m.E1, -nu13 / m.E1],
                 [-m.nu12 / m.E1, 1.0 / m.E2, -nu23 / m.E2],
                 [-nu13 / m.E1, -nu23 / m.E2, 1.0 / E3]]
    # G23 and G13 decouple from the plane under rotations about z: any positive value will do.
    S[[3, 4, 5], [3, 4, 5]] = [1.0 / m.G12, 1.0 / m.G12, 1.0 / m.G12]
    check_positive_definite(S[:3, :3], "the orthotropic compliance (E1, E2, E3, nu12, nu13, nu23)")
    return _rotate_about_z(np.linalg.inv(S), math.radians(m.angle))


def _rotate_about_z(C: np.ndarray, angle: float) -> np.ndarray:
    """Rotate a 6×6 Voigt stiffness by ``angle`` (radians) about z, as a fourth-order tensor."""
    if angle == 0.0:
        return C
    cos, sin = math.cos(angle), math.sin(angle)
    return _rotated(C, np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]]))


def _rotated(C: np.ndarray, R: np.ndarray) -> np.ndarray:
    """A 6×6 Voigt stiffness given in the frame of ``R``'s columns, as a fourth-order tensor in x, y, z."""
    pairs = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    tensor = np.zeros((3, 3, 3, 3))
    for I, (i, j) in enumerate(pairs):
        for J, (k, l) in enumerate(pairs):
            for a, b in {(i, j), (j, i)}:
                for c, d in {(k, l), (l, k)}:
                    tensor[a, b, c, d] = C[I, J]
    rotated = np.einsum("ia,jb,kc,ld,abcd->ijkl", R, R, R, R, tensor)
    return np.array([[rotated[i, j, k, l] for k, l in pairs] for i, j in pairs])


def fibre_direction(material: Orthotropic) -> np.ndarray:
    """The unit fibre direction in 3-D: ``fibre`` normalised, else ``angle`` degrees from x towards y (about z, as in
    the plane)."""
    if material.fibre is not None:
        fibre = np.asarray(material.fibre, dtype=float)
        fibre = fibre / np.abs(fibre).max()  # first to about 1: the norm of huge or tiny numbers over- or underflows
        return fibre / np.linalg.norm(fibre)
    angle = math.radians(material.angle)
    return np.array([math.cos(angle), math.sin(angle), 0.0])


def _fibre_frame(fibre: np.ndarray) -> np.ndarray:
    """A rotation whose first column is the unit ``fibre`` (the other two: any right-handed orthonormal pair)."""
    helper = np.eye(3)[np.argmin(np.abs(fibre))]
    second = np.cross(helper, fibre)
    second /= np.linalg.norm(second)
    return np.column_stack([fibre, second, np.cross(fibre, second)])


def solid_stiffness(material: Isotropic | Orthotropic) -> np.ndarray:
    """The 6×6 Voigt stiffness (engineering shears) of a 3-D body: isotropic, or a transversely isotropic ply about
    its fibre (:func:`fibre_direction`): E3 = E2, ν13 = ν12, G13 = G12 and G23 = E2/(2(1 + ν23)), ν23 defaulting to
    ν12."""
    if isinstance(material, Isotropic):
        return stiffness_3d(material)
    m = material
    nu23 = m.nu12 if m.nu23 is None else m.nu23
    S = np.zeros((6, 6))
    S[:3, :3] = [[1.0 / m.E1, -m.nu12 / m.E1, -m.nu12 / m.E1],
                 [-m.nu12 / m.E1, 1.0 / m.E2, -nu23 / m.E2],
                 [-m.nu12 / m.E1, -nu23 / m.E2, 1.0 / m.E2]]
    S[[3, 4, 5], [3, 4, 5]] = [2.0 * (1.0 + nu23) / m.E2, 1.0 / m.G12, 1.0 / m.G12]
    check_positive_definite(S, "the transversely isotropic compliance (E1, E2, G12, nu12, nu23)")
    return _rotated(np.linalg.inv(S), _fibre_frame(fibre_direction(m)))


def solid_expansion(material: Isotropic | Orthotropic) -> np.ndarray:
    """The 3-D eigenstrain per unit temperature change ``(6,)`` (Voigt, engineering shears): α I, or
    α2 I + (α1 − α2) f ⊗ f about the fibre f."""
    if isinstance(material, Isotropic):
        return expansion(material)
    f = fibre_direction(material)
    along = np.array([f[0] ** 2, f[1] ** 2, f[2] ** 2, 2.0 * f[1] * f[2], 2.0 * f[0] * f[2], 2.0 * f[0] * f[1]])
    return material.alpha2 * np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0]) + (material.alpha1 - material.alpha2) * along


def von_mises(stress: np.ndarray, szz: np.ndarray) -> np.ndarray:
    """Von Mises stress of (σxx, σyy, σxy) rows ``(m, 3)`` with σzz ``(m,)``."""
    sxx, syy, sxy = stress.T
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * sxy ** 2)
