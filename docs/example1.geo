// The paper's geometry as a gmsh script: the square (-1, 1)^2 cut by Sigma along y = 0, the crack
// on (-1/2, 1/2), both layers clamped at x = -1 and x = 1. ddsolve meshes it (mesh.file = "example1.geo")
// with the element size of the scene's mesh.size; the physical groups below are what ddsolve reads.
lc = 1.0;  // the size comes from mesh.size (gmsh's Mesh.MeshSizeMax); smaller lc here would refine locally
Point(1) = {-1, -1, 0, lc}; Point(2) = {1, -1, 0, lc}; Point(3) = {1, 1, 0, lc}; Point(4) = {-1, 1, 0, lc};
Point(5) = {-1, 0, 0, lc}; Point(6) = {-0.5, 0, 0, lc}; Point(7) = {0.5, 0, 0, lc}; Point(8) = {1, 0, 0, lc};
Line(1) = {1, 2};                          // bottom
Line(2) = {2, 8}; Line(3) = {8, 3};        // right side, lower and upper
Line(4) = {3, 4};                          // top
Line(5) = {4, 5}; Line(6) = {5, 1};        // left side, upper and lower
Line(7) = {5, 6}; Line(8) = {6, 7}; Line(9) = {7, 8};  // Sigma: glued, crack, glued
Curve Loop(1) = {1, 2, -9, -8, -7, 6};  Plane Surface(1) = {1};
Curve Loop(2) = {7, 8, 9, 3, 4, 5};     Plane Surface(2) = {2};
Physical Surface("lower") = {1};
Physical Surface("upper") = {2};
Physical Curve("sigma") = {7, 8, 9};
Physical Curve("crack") = {8};
Physical Curve("clamped") = {2, 3, 5, 6};
Physical Curve("bottom") = {1};
Physical Curve("top") = {4};
