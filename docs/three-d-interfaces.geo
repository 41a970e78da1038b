// The 3-D box of two interfaces of docs/three-d-interfaces.toml as a gmsh geometry: the box [0, 4] x [0, 3] x [0, 1]
// cut by the planes y = 1 and y = 2 into three regions, a crack on each (on the lower the rectangle 1 < x < 2,
// 0.25 < z < 0.75; on the upper 2 < x < 3 across the depth).  Built as ddsolve builds its 3-D box (the boxes between
// the interfaces and the cracks' rectangles fragmented together, sizes from mesh.size alone), so that the same
// mesh.size gives the same tetrahedra.  ddsolve reads the physical groups: the surfaces sigma1, sigma2 (bottom to
// top, planes y = const), crack1 on sigma1 and crack2 on sigma2, one volume per region listed bottom to top (their
// names name the regions for materials), clamped, and names for loads.
SetFactory("OpenCASCADE");
Mesh.Algorithm = 5;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromCurvature = 0;

x0 = 0; x1 = 4; y0 = 0; y1 = 3; z0 = 0; z1 = 1;  // the body
s1 = 1; s2 = 2;                                  // the interfaces: the planes y = s1 and y = s2

Box(1) = {x0, y0, z0, x1 - x0, s1 - y0, z1 - z0};
Box(2) = {x0, s1, z0, x1 - x0, s2 - s1, z1 - z0};
Box(3) = {x0, s2, z0, x1 - x0, y1 - s2, z1 - z0};
c1 = news;
Rectangle(c1) = {1, 0.25, 0, 1, 0.5};            // made in the x-y plane, turned onto Σ: (x, y, 0) -> (x, s, y)
Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{c1}; }
Translate {0, s1, 0} { Surface{c1}; }
c2 = news;
Rectangle(c2) = {2, z0, 0, 1, z1 - z0};
Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{c2}; }
Translate {0, s2, 0} { Surface{c2}; }
BooleanFragments{ Volume{1, 2, 3}; Delete; }{ Surface{c1, c2}; Delete; }

e = 1e-6;
Physical Volume("base") = Volume In BoundingBox{x0 - e, y0 - e, z0 - e, x1 + e, s1 + e, z1 + e};
Physical Volume("core") = Volume In BoundingBox{x0 - e, s1 - e, z0 - e, x1 + e, s2 + e, z1 + e};
Physical Volume("cover") = Volume In BoundingBox{x0 - e, s2 - e, z0 - e, x1 + e, y1 + e, z1 + e};
Physical Surface("sigma1") = Surface In BoundingBox{x0 - e, s1 - e, z0 - e, x1 + e, s1 + e, z1 + e};
Physical Surface("crack1") = Surface In BoundingBox{1 - e, s1 - e, 0.25 - e, 2 + e, s1 + e, 0.75 + e};
Physical Surface("sigma2") = Surface In BoundingBox{x0 - e, s2 - e, z0 - e, x1 + e, s2 + e, z1 + e};
Physical Surface("crack2") = Surface In BoundingBox{2 - e, s2 - e, z0 - e, 3 + e, s2 + e, z1 + e};
Physical Surface("clamped") = Surface In BoundingBox{x0 - e, y0 - e, z0 - e, x0 + e, y1 + e, z1 + e};
Physical Surface("right") = Surface In BoundingBox{x1 - e, y0 - e, z0 - e, x1 + e, y1 + e, z1 + e};
Physical Surface("bottom") = Surface In BoundingBox{x0 - e, y0 - e, z0 - e, x1 + e, y0 + e, z1 + e};
Physical Surface("top") = Surface In BoundingBox{x0 - e, y1 - e, z0 - e, x1 + e, y1 + e, z1 + e};
