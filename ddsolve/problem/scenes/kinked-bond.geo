// A bond line with a kink: Sigma runs straight from (-1, 0) up to (0, 0.3) and down to (1, 0);
// the crack runs from x = -0.4 to x = 0.4 through the kink.
lc = 1.0;  // the element size comes from the scene's mesh.size (gmsh Mesh.MeshSizeMax)
Point(1) = {-1, -1, 0, lc}; Point(2) = {1, -1, 0, lc}; Point(3) = {1, 1, 0, lc}; Point(4) = {-1, 1, 0, lc};
Point(5) = {-1, 0, 0, lc}; Point(6) = {-0.4, 0.18, 0, lc}; Point(7) = {0, 0.3, 0, lc};
Point(8) = {0.4, 0.18, 0, lc}; Point(9) = {1, 0, 0, lc};
Line(1) = {1, 2};                          // bottom
Line(2) = {2, 9}; Line(3) = {9, 3};        // right side
Line(4) = {3, 4};                          // top
Line(5) = {4, 5}; Line(6) = {5, 1};        // left side
Line(7) = {5, 6}; Line(8) = {6, 7}; Line(9) = {7, 8}; Line(10) = {8, 9};  // Sigma
Curve Loop(1) = {1, 2, -10, -9, -8, -7, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {7, 8, 9, 10, 3, 4, 5};     Plane Surface(2) = {2};
Physical Surface("lower") = {1};
Physical Surface("upper") = {2};
Physical Curve("sigma") = {7, 8, 9, 10};
Physical Curve("crack") = {8, 9};
Physical Curve("clamped") = {2, 3, 5, 6};
Physical Curve("bottom") = {1};
Physical Curve("top") = {4};
