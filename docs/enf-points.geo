// End-notched flexure (ASTM D7905 proportions, L = 20 h): a strip (0, 40) x (-1, 1) of arm thickness h = 1,
// Sigma its mid-plane, an edge crack (0, 10) on it. Supported on two physical points: the pin at the
// lower left corner, the roller at the lower right corner; loaded at midspan on the top segment "load"
// (width 0.2: a point force has infinite energy in plane elasticity). The size comes from mesh.size.
lc = 1.0;
Point(1) = {0, -1, 0, lc};      // pin
Point(2) = {40, -1, 0, lc};     // roller
Point(3) = {40, 0, 0, lc};
Point(4) = {40, 1, 0, lc};
Point(5) = {20.1, 1, 0, lc};
Point(6) = {19.9, 1, 0, lc};
Point(7) = {0, 1, 0, lc};
Point(8) = {0, 0, 0, lc};       // the crack's mouth
Point(9) = {10, 0, 0, 0.02};    // the crack tip, with elements of 0.02 around it
Line(1) = {1, 2};               // bottom
Line(2) = {2, 3};               // right end, lower arm
Line(3) = {3, 4};               // right end, upper arm
Line(4) = {4, 5};               // top, right of the load
Line(5) = {5, 6};               // load
Line(6) = {6, 7};               // top, left of the load
Line(7) = {7, 8};               // left end, upper arm
Line(8) = {8, 1};               // left end, lower arm
Line(9) = {8, 9};               // the crack
Line(10) = {9, 3};              // the glued part of Sigma
Curve Loop(1) = {1, 2, -10, -9, 8};       Plane Surface(1) = {1};
Curve Loop(2) = {9, 10, 3, 4, 5, 6, 7};   Plane Surface(2) = {2};
Physical Surface("lower") = {1};
Physical Surface("upper") = {2};
Physical Curve("sigma") = {9, 10};
Physical Curve("crack") = {9};
Physical Curve("load") = {5};
Physical Curve("bottom") = {1};
Physical Curve("top") = {4, 6};
Physical Point("pin") = {1};
Physical Point("roller") = {2};
