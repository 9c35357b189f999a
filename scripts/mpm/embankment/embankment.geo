// Half of a symmetric embankment on a foundation layer, plane strain, metres (gmsh).
//   gmsh -2 -setnumber slope 1.5 -format msh41 embankment.geo -o embankment_slope1.5.msh
// The embankment: height H, crest half-width a, slopes of `slope` horizontal to 1 vertical,
// its axis of symmetry on x = 0. The foundation: depth D under the embankment's base, to x = L.
// Physical groups: surfaces "embankment" and "foundation"; curves "base" (y = -D), "axis"
// (x = 0, the symmetry plane) and "far" (x = L), and "face" (the slope, for pictures).
If (!Exists(slope))
  slope = 2;
EndIf
H = 5; a = 4; D = 5; L = 24;
toe = a + slope * H;
size = 0.5;

Point(1) = {0, -D, 0, size};
Point(2) = {L, -D, 0, size};
Point(3) = {L, 0, 0, size};
Point(4) = {toe, 0, 0, size};
Point(5) = {a, H, 0, size};
Point(6) = {0, H, 0, size};
Point(7) = {0, 0, 0, size};

Line(1) = {1, 2};   // base
Line(2) = {2, 3};   // far side of the foundation
Line(3) = {3, 4};   // ground beyond the toe
Line(4) = {4, 5};   // slope face
Line(5) = {5, 6};   // crest
Line(6) = {6, 7};   // axis, embankment
Line(7) = {7, 1};   // axis, foundation
Line(8) = {7, 4};   // embankment's base on the foundation

Curve Loop(1) = {1, 2, 3, -8, 7};
Plane Surface(1) = {1};
Curve Loop(2) = {8, 4, 5, 6};
Plane Surface(2) = {2};

Physical Surface("foundation") = {1};
Physical Surface("embankment") = {2};
Physical Curve("base") = {1};
Physical Curve("axis") = {6, 7};
Physical Curve("far") = {2};
Physical Curve("face") = {4};
