# YADE side of the granite/YADE comparison (tests/yade_comparison.rs runs it; by hand:
#   yade -n -x tests/yade/yade_run.py STATE.json OUT.csv steps=N every=K [name=value ...]
# STATE.json is a DEM state saved by granite (`sim.save`): spheres with positions, radii,
# velocities and spins, planar walls or a periodic cell, gravity, damping, time step and one
# `linear` law. The same scene is built with YADE's standard engines (ScGeom, FrictPhys,
# CundallStrack, NewtonIntegrator) and run; every `every` steps a row of OUT.csv gets the
# Love-Weber stress (periodic cell), the kinetic energy, the vertical force on the last wall (the floor of a granite box) and the
# number of contacts. Optional values: young (Pa), kt_ratio, friction (degrees), damping, and
# l_xx, l_yy, l_zz, l_xz, the cell's velocity gradient (1/s), all overriding the state's; law=rolling_resistance with
# alpha_r, alpha_t and eta_r gives the grains granite's `rolling_resistance` law instead
# (CohFrictMat without cohesion, ScGeom6D, the incremental CohesionMoment law);
# law=hertz_mindlin with young and poisson gives granite's `hertz_mindlin` (MindlinPhys).
import json
import math
import sys

from yade import utils

state_path, out_path = sys.argv[1], sys.argv[2]
options = dict(arg.split("=", 1) for arg in sys.argv[3:])
steps, every = int(options.pop("steps")), int(options.pop("every"))

with open(state_path) as f:
    state = json.load(f)
# A saved file wraps the state with its format and checksum.
state = state.get("state", state)
laws = state["laws"]
if len(laws) != 1 or laws[0]["name"] != "linear" or "young" not in laws[0]["params"]:
    sys.exit("the state must use one `linear` law given by `young` (kn = 2 E r1 r2 / (r1 + r2))")
law = laws[0]["params"]
friction = float(options.pop("friction", law.get("friction", 0.0)))
damping = float(options.pop("damping", state["damping"]))
gradient = {k: float(options.pop(k, 0.0)) for k in ("l_xx", "l_yy", "l_zz", "l_xz")}
law_name = options.pop("law", "linear")
rolling, hertz = law_name == "rolling_resistance", law_name == "hertz_mindlin"
alpha_r, alpha_t, eta_r = (float(options.pop(k, d)) for k, d in (("alpha_r", 7.5), ("alpha_t", 0.2), ("eta_r", 0.22)))
young = float(options.pop("young", law["young"]))
kt_ratio = float(options.pop("kt_ratio", law.get("kt_ratio", 0.0)))
poisson = float(options.pop("poisson", 0.25))
if options:
    sys.exit(f"unknown options {sorted(options)}")
density = state["materials"][0]["density"]

# FrictMat's `poisson` is YADE's ks/kn in FrictPhys and CohFrictPhys, and kn = 2 E1 R1 E2 R2 /
# (E1 R1 + E2 R2) as granite's `young` (a wall counts as a sphere of the grain's radius in both);
# MindlinPhys reads the true Poisson ratio: E* = E / (2 (1 - nu^2)), G* = G / (2 (2 - nu)).
common = dict(young=young, frictionAngle=math.radians(friction), density=density)
if rolling:
    # k_r = alpha_r kt r1 r2, k_tw = alpha_t kt r1 r2, both capped at eta_r |F_n| min(r1, r2).
    material = CohFrictMat(
        poisson=kt_ratio,
        isCohesive=False,
        momentRotationLaw=True,
        alphaKr=alpha_r,
        alphaKtw=alpha_t,
        etaRoll=eta_r,
        etaTwist=eta_r,
        **common,
    )
else:
    material = FrictMat(poisson=poisson if hertz else kt_ratio, **common)
material = O.materials.append(material)
walls = []
for wall in state["walls"]:
    normal = wall["shape"].get("Plane", {}).get("normal")
    axes = [a for a in range(3) if normal is not None and normal[a] != 0.0]
    if len(axes) != 1 or any(normal[a] != 0.0 for a in range(3) if a != axes[0]):
        sys.exit("only planar walls normal to an axis are translated")
    axis = axes[0]
    sense = 1 if normal[axis] > 0 else -1
    walls.append(O.bodies.append(utils.wall(wall["position"][axis], axis=axis, sense=sense, material=material)))
spheres = state["spheres"]
sphere_ids = []
for x, r, v, w in zip(spheres["x"], spheres["radius"], spheres["v"], spheres["w"]):
    body = utils.sphere(Vector3(*x), r, material=material)
    body.state.vel = Vector3(*v)
    body.state.angVel = Vector3(*w)
    sphere_ids.append(O.bodies.append(body))
# Clumps: YADE sums its members' masses (overlaps counted twice); granite integrated the union by
# voxels, so the clump takes granite's mass and principal inertia (the tetrahedral clumps of the
# comparison are isotropic, so the principal frame does not matter), velocity and spin.
clumps = state["clumps"]
for c in range(len(clumps["mass"])):
    members = clumps["members"][clumps["start"][c] : clumps["start"][c + 1]]
    clump = O.bodies[O.bodies.clump([sphere_ids[m] for m in members])]
    clump.state.mass = clumps["mass"][c]
    clump.state.inertia = Vector3(*clumps["inertia"][c])
    clump.state.vel = Vector3(*clumps["v"][c])
    clump.state.angVel = Vector3(*clumps["w"][c])

if state.get("cell"):
    O.periodic = True
    h = state["cell"]["h"]  # nalgebra stores matrices column by column
    O.cell.hSize = Matrix3(h[0], h[3], h[6], h[1], h[4], h[7], h[2], h[5], h[8])
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()]),
    InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom6D(), Ig2_Wall_Sphere_ScGeom()] if rolling else [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
        [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys()]
        if rolling
        else [Ip2_FrictMat_FrictMat_MindlinPhys()]
        if hertz
        else [Ip2_FrictMat_FrictMat_FrictPhys()],
        [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(useIncrementalForm=True, always_use_moment_law=True)]
        if rolling
        else [Law2_ScGeom_MindlinPhys_Mindlin()]
        if hertz
        else [Law2_ScGeom_FrictPhys_CundallStrack()],
    ),
    NewtonIntegrator(damping=damping, gravity=Vector3(*state["gravity"])),
]
O.dt = state["dt"]
if O.periodic:
    g = gradient
    O.cell.velGrad = Matrix3(g["l_xx"], 0, g["l_xz"], 0, g["l_yy"], 0, 0, 0, g["l_zz"])

with open(out_path, "w") as out:
    out.write("step,sxx,syy,szz,sxz,kinetic_energy,wall_force_z,contacts\n")

    def record(step):
        s = utils.getStress() if O.periodic else Matrix3.Zero
        wall_force = O.forces.f(walls[-1])[2] if walls else 0.0
        contacts = sum(1 for i in O.interactions if i.isReal)
        values = [s[0, 0], s[1, 1], s[2, 2], s[0, 2], utils.kineticEnergy(), wall_force]
        out.write(f"{step}," + ",".join(repr(float(v)) for v in values) + f",{contacts}\n")

    record(0)
    for k in range(every, steps + 1, every):
        O.run(every, True)
        record(k)
