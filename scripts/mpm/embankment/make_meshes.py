"""Writes embankment_slope2.msh and embankment_slope1.5.msh from embankment.geo with gmsh's
Python API (pip install gmsh): MSH 4.1, ASCII. (The same as
`gmsh -2 -setnumber slope 1.5 -format msh41 embankment.geo -o embankment_slope1.5.msh`.)"""
import os
import tempfile

import gmsh

here = os.path.dirname(os.path.abspath(__file__))
geo = open(os.path.join(here, "embankment.geo")).read()
for slope in (2.0, 1.5):
    with tempfile.NamedTemporaryFile("w", suffix=".geo", delete=False) as f:
        f.write(f"slope = {slope};\n" + geo)
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(f.name)
    gmsh.model.mesh.generate(2)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.write(os.path.join(here, f"embankment_slope{slope:g}.msh"))
    gmsh.finalize()
    os.unlink(f.name)
