// The extruded partly closed scene of docs/three-d.md as a 3-D gmsh geometry: the square [-1, 1]² cut by Σ at
// y = 0, extruded over z in [0, 0.5], the crack -0.5 < x < 0.5 across the depth.  Built as ddsolve builds its
// 3-D box (two boxes and the crack's rectangle fragmented together, sizes from mesh.size alone), so that the
// same mesh.size gives the same tetrahedra.  ddsolve reads the physical groups: the volumes lower and upper,
// the surfaces sigma (the plane y = const between them), crack (on sigma), clamped, and names for loads.
SetFactory("OpenCASCADE");
Mesh.Algorithm = 5;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromCurvature = 0;

x0 = -1; x1 = 1; y0 = -1; y1 = 1; z0 = 0; z1 = 0.5;  // the body
ys = 0;                                             // Σ: the plane y = ys
a = -0.5; b = 0.5;                                  // the crack: a < x < b, across the depth

Box(1) = {x0, y0, z0, x1 - x0, ys - y0, z1 - z0};
Box(2) = {x0, ys, z0, x1 - x0, y1 - ys, z1 - z0};
s = news;
Rectangle(s) = {a, z0, 0, b - a, z1 - z0};          // made in the x-y plane, turned onto Σ: (x, y, 0) -> (x, 0, y)
Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{s}; }
Translate {0, ys, 0} { Surface{s}; }
BooleanFragments{ Volume{1, 2}; Delete; }{ Surface{s}; Delete; }

e = 1e-6;
Physical Volume("lower") = Volume In BoundingBox{x0 - e, y0 - e, z0 - e, x1 + e, ys + e, z1 + e};
Physical Volume("upper") = Volume In BoundingBox{x0 - e, ys - e, z0 - e, x1 + e, y1 + e, z1 + e};
Physical Surface("sigma") = Surface In BoundingBox{x0 - e, ys - e, z0 - e, x1 + e, ys + e, z1 + e};
Physical Surface("crack") = Surface In BoundingBox{a - e, ys - e, z0 - e, b + e, ys + e, z1 + e};
left() = Surface In BoundingBox{x0 - e, y0 - e, z0 - e, x0 + e, y1 + e, z1 + e};
right() = Surface In BoundingBox{x1 - e, y0 - e, z0 - e, x1 + e, y1 + e, z1 + e};
Physical Surface("clamped") = {left(), right()};
Physical Surface("bottom") = Surface In BoundingBox{x0 - e, y0 - e, z0 - e, x1 + e, y0 + e, z1 + e};
Physical Surface("top") = Surface In BoundingBox{x0 - e, y1 - e, z0 - e, x1 + e, y1 + e, z1 + e};
Physical Surface("front") = Surface In BoundingBox{x0 - e, y0 - e, z0 - e, x1 + e, y1 + e, z0 + e};
Physical Surface("back") = Surface In BoundingBox{x0 - e, y0 - e, z1 - e, x1 + e, y1 + e, z1 + e};
