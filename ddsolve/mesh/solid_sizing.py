"""A size field for gmsh's 3-D mesher from sizes at the vertices of an old mesh: the old tetrahedra as a list-based
post-processing view of scalar tetrahedra (``SS``), its piecewise linear field the only source of element sizes
(``PostView`` as the background mesh; sizes from points, curvature and the boundary off), capped by
``Mesh.MeshSizeMax``.  Used by adaptive re-meshing (:mod:`ddsolve.solvers.solid_adapt`) in gmsh's child process."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SizeField:
    """The wanted element size at every vertex ``(n,)`` of the tetrahedra ``(m, 4)`` over ``points`` ``(n, 3)``."""

    points: np.ndarray
    tetrahedra: np.ndarray
    sizes: np.ndarray


def as_background(gmsh, field: SizeField) -> None:
    """Make ``field`` gmsh's background mesh, the only source of element sizes."""
    corners = field.points[field.tetrahedra].transpose(0, 2, 1).reshape(len(field.tetrahedra), 12)  # x…, y…, z…
    data = np.column_stack([corners, field.sizes[field.tetrahedra]])
    view = gmsh.view.add("element sizes")
    gmsh.view.addListData(view, "SS", len(data), data.ravel().tolist())
    fields = gmsh.model.mesh.field
    background = fields.add("PostView")
    fields.setNumber(background, "ViewTag", view)
    fields.setAsBackgroundMesh(background)
    for option in ("Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature", "Mesh.MeshSizeExtendFromBoundary"):
        gmsh.option.setNumber(option, 0)
