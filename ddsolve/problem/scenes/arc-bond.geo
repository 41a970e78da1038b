// A curved bond line: Sigma is a circular arc from (-1, 0) through (0, 0.2) to (1, 0) in the
// square (-1, 1)^2, with a crack on its middle part between x = -0.5 and x = 0.5.
lc = 1.0;  // the element size comes from the scene's mesh.size (gmsh Mesh.MeshSizeMax)
r = 2.6; yc = -2.4;  // centre (0, yc), radius r: the arc rises 0.2 over its chord of length 2
ya = yc + Sqrt(r^2 - 0.25);  // height of the arc at x = +-0.5
Point(1) = {-1, -1, 0, lc}; Point(2) = {1, -1, 0, lc}; Point(3) = {1, 1, 0, lc}; Point(4) = {-1, 1, 0, lc};
Point(5) = {-1, 0, 0, lc}; Point(6) = {-0.5, ya, 0, lc}; Point(7) = {0.5, ya, 0, lc}; Point(8) = {1, 0, 0, lc};
Point(9) = {0, yc, 0, lc};
Line(1) = {1, 2};                          // bottom
Line(2) = {2, 8}; Line(3) = {8, 3};        // right side, below and above Sigma
Line(4) = {3, 4};                          // top
Line(5) = {4, 5}; Line(6) = {5, 1};        // left side, above and below Sigma
Circle(7) = {5, 9, 6}; Circle(8) = {6, 9, 7}; Circle(9) = {7, 9, 8};  // Sigma: glued, crack, glued
Curve Loop(1) = {1, 2, -9, -8, -7, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {7, 8, 9, 3, 4, 5};    Plane Surface(2) = {2};
Physical Surface("lower") = {1};
Physical Surface("upper") = {2};
Physical Curve("sigma") = {7, 8, 9};
Physical Curve("crack") = {8};
Physical Curve("clamped") = {2, 3, 5, 6};
Physical Curve("bottom") = {1};
Physical Curve("top") = {4};
