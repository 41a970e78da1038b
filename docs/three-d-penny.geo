// A quarter of a penny-shaped crack (radius 0.5, centre on the axis x = z = 0) in the block [0, 2] × [-2, 2] ×
// [0, 2], Σ the plane y = 0: the quarter model of docs/three-d-front.md by symmetry about x = 0 and z = 0.  Built as
// ddsolve builds its 3-D box with an ellipse crack (sizes from mesh.size alone).  ddsolve reads the physical
// groups: the volumes lower and upper, the surfaces sigma and crack (on sigma), and names for loads and supports.
SetFactory("OpenCASCADE");
Mesh.Algorithm = 5;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromCurvature = 0;

L = 2;                                              // the block [0, L] × [-L, L] × [0, L]
r = 0.5;                                            // the penny's radius

Box(1) = {0, -L, 0, L, L, L};
Box(2) = {0, 0, 0, L, L, L};
d = news;
Disk(d) = {0, 0, 0, r, r};                          // made in the x-y plane, turned onto Σ: (x, y, 0) -> (x, 0, y)
q = news;
Rectangle(q) = {0, 0, 0, L, L};
quarter() = BooleanIntersection{ Surface{d}; Delete; }{ Surface{q}; Delete; };
Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{quarter()}; }
BooleanFragments{ Volume{1, 2}; Delete; }{ Surface{quarter()}; Delete; }

e = 1e-6;
Physical Volume("lower") = Volume In BoundingBox{-e, -L - e, -e, L + e, e, L + e};
Physical Volume("upper") = Volume In BoundingBox{-e, -e, -e, L + e, L + e, L + e};
Physical Surface("sigma") = Surface In BoundingBox{-e, -e, -e, L + e, e, L + e};
Physical Surface("crack") = Surface In BoundingBox{-e, -e, -e, r + e, e, r + e};
Physical Surface("bottom") = Surface In BoundingBox{-e, -L - e, -e, L + e, -L + e, L + e};
Physical Surface("top") = Surface In BoundingBox{-e, L - e, -e, L + e, L + e, L + e};
Physical Surface("left") = Surface In BoundingBox{-e, -L - e, -e, e, L + e, L + e};
Physical Surface("front") = Surface In BoundingBox{-e, -L - e, -e, L + e, L + e, e};
