"""Writes silo_outlet_<D>mm.stl: a square flat-bottomed silo (60 mm wide, 140 mm high) with a
circular outlet of diameter D mm centred in its floor, as triangles (ASCII STL, millimetres).
silo_discharge.rhai reads them; run `python3 make_silo.py` to make them again."""
import math

WIDTH, HEIGHT, SEGMENTS = 60.0, 140.0, 64


def silo(outlet):
    c, r = WIDTH / 2, outlet / 2
    tris = []
    # The floor: between the outlet's circle and the square, along rays at equal angles (the
    # square's corners fall on rays 8, 24, 40, 56).
    def on_square(t):
        dx, dy = math.cos(t), math.sin(t)
        s = (WIDTH / 2) / max(abs(dx), abs(dy))
        return (c + s * dx, c + s * dy, 0.0)

    for k in range(SEGMENTS):
        t0, t1 = 2 * math.pi * k / SEGMENTS, 2 * math.pi * (k + 1) / SEGMENTS
        a0 = (c + r * math.cos(t0), c + r * math.sin(t0), 0.0)
        a1 = (c + r * math.cos(t1), c + r * math.sin(t1), 0.0)
        b0, b1 = on_square(t0), on_square(t1)
        tris += [(a0, b0, b1), (a0, b1, a1)]
    # The four sides.
    corners = [(0, 0), (WIDTH, 0), (WIDTH, WIDTH), (0, WIDTH)]
    for k in range(4):
        (x0, y0), (x1, y1) = corners[k], corners[(k + 1) % 4]
        p = [(x0, y0, 0.0), (x1, y1, 0.0), (x1, y1, HEIGHT), (x0, y0, HEIGHT)]
        tris += [(p[0], p[1], p[2]), (p[0], p[2], p[3])]
    return tris


for outlet in (12, 15, 18):
    with open(f"silo_outlet_{outlet}mm.stl", "w") as f:
        f.write(f"solid silo_outlet_{outlet}mm\n")
        for t in silo(outlet):
            f.write("facet normal 0 0 0\n outer loop\n")
            for v in t:
                f.write(f"  vertex {v[0]!r} {v[1]!r} {v[2]!r}\n")
            f.write(" endloop\nendfacet\n")
        f.write(f"endsolid silo_outlet_{outlet}mm\n")
