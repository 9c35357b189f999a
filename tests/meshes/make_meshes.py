"""Writes the gmsh test meshes of tests/meshes with gmsh's Python API (pip install gmsh).

embankment_*.msh: a trapezoidal embankment on a rectangular foundation (plane, metres), in the
four encodings granite reads (MSH 4.1 and 2.2, ASCII and binary); embankment_order2.msh: the
same with second-order elements; wedge_block.msh: a 3D block with a sloping top, of
tetrahedra, with its base surface named.
"""
import gmsh

FOUNDATION = [(0, 0), (10, 0), (10, 2), (7, 2), (3, 2), (0, 2)]
EMBANKMENT = [(3, 2), (7, 2), (5.5, 3.5), (4.5, 3.5)]


def embankment(path, version, binary, order=1):
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("embankment")
    g = gmsh.model.geo
    corners = [(0, 0), (10, 0), (10, 2), (7, 2), (5.5, 3.5), (4.5, 3.5), (3, 2), (0, 2)]
    p = [g.addPoint(x, y, 0, 0.5) for x, y in corners]
    l = [g.addLine(p[i], p[(i + 1) % 8]) for i in range(8)]
    crest_base = g.addLine(p[6], p[3])
    foundation = g.addPlaneSurface([g.addCurveLoop([l[0], l[1], l[2], -crest_base, l[6], l[7]])])
    body = g.addPlaneSurface([g.addCurveLoop([l[3], l[4], l[5], crest_base])])
    g.synchronize()
    gmsh.model.addPhysicalGroup(2, [foundation], name="foundation")
    gmsh.model.addPhysicalGroup(2, [body], name="embankment")
    gmsh.model.addPhysicalGroup(1, [l[0]], name="base")
    gmsh.model.addPhysicalGroup(1, [l[7], l[1]], name="sides")
    gmsh.model.addPhysicalGroup(1, [l[3], l[4], l[5]], name="slope")
    gmsh.model.mesh.generate(2)
    if order > 1:
        gmsh.model.mesh.setOrder(order)
    gmsh.option.setNumber("Mesh.MshFileVersion", version)
    gmsh.option.setNumber("Mesh.Binary", binary)
    gmsh.write(path)
    gmsh.finalize()


def wedge_block(path):
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("wedge")
    # A 1 x 1 base, 0.5 high at x = 0 and 0.25 high at x = 1.
    g = gmsh.model.geo
    pts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 0.5), (1, 0, 0.25), (1, 1, 0.25), (0, 1, 0.5)]
    p = [g.addPoint(*x, 0.25) for x in pts]
    edges = {}

    def line(a, b):
        if (b, a) in edges:
            return -edges[(b, a)]
        edges[(a, b)] = g.addLine(p[a], p[b])
        return edges[(a, b)]

    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    surfaces = []
    for f in faces:
        loop = g.addCurveLoop([line(f[i], f[(i + 1) % 4]) for i in range(4)])
        surfaces.append(g.addPlaneSurface([loop]))
    volume = g.addVolume([g.addSurfaceLoop(surfaces)])
    g.synchronize()
    gmsh.model.addPhysicalGroup(3, [volume], name="block")
    gmsh.model.addPhysicalGroup(2, [surfaces[0]], name="bottom")
    gmsh.model.mesh.generate(3)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 1)
    gmsh.write(path)
    gmsh.finalize()


for version, binary, name in [(4.1, 0, "v41_ascii"), (4.1, 1, "v41_binary"), (2.2, 0, "v22_ascii"), (2.2, 1, "v22_binary")]:
    embankment(f"embankment_{name}.msh", version, binary)
embankment("embankment_order2.msh", 4.1, 0, order=2)
wedge_block("wedge_block.msh")
