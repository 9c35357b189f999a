//! The script API described once: every function and property scripts can call, with its
//! argument names, the option keys it accepts and one line of documentation. `:help`, `:api`,
//! tab completion and "did you mean" in `granite repl`, and `docs/api.md` (`granite api`), all
//! read this table; a test checks that it names exactly the functions the engine registers, and
//! the functions that take options check their keys against it.

/// One function (all its overloads) or property of the script API.
#[derive(Debug, Clone, Copy)]
pub struct ApiDoc {
    /// What it is called on: `""` (a global function), `"sim"` (both simulations), `"MpmSim"`,
    /// `"DemSim"`, `"Material"` (an MPM material), `"DemMaterial"`, `"DemWall"`, `"Mesh"` (a gmsh mesh), or a Rhai type (`"array"`,
    /// `"string"`, `"blob"`) for the few of Rhai's own functions granite replaces.
    pub on: &'static str,
    pub name: &'static str,
    /// How it is called, with argument names; a property has no parentheses.
    pub forms: &'static [&'static str],
    /// Keys of its options map (`#{ ... }`), if it takes one.
    pub options: &'static [&'static str],
    pub doc: &'static str,
}

const fn f(
    on: &'static str,
    name: &'static str,
    forms: &'static [&'static str],
    options: &'static [&'static str],
    doc: &'static str,
) -> ApiDoc {
    ApiDoc { on, name, forms, options, doc }
}

const NONE: &[&str] = &[];
const FILL: &[&str] = &["per_cell", "layout", "velocity", "stress"];
const MESH: &[&str] = &["dim", "origin", "cell", "cells"];
const LIMITS: &[&str] = &["min", "max", "above", "below", "one_of"];

/// The whole API, grouped as docs/api.md shows it.
pub static API: &[ApiDoc] = &[
    // Global functions.
    f("", "param", &["param(name, default)", "param(name, default, #{ limits })"], LIMITS, "a script parameter that `--set name=value` overrides, parsed like its default; the limits are checked at this line"),
    f("", "summary", &["summary(name, value)"], NONE, "a result written to summary.json"),
    f("", "out_dir", &["out_dir()"], NONE, "this run's output folder"),
    f("", "print_line", &["print_line(text)"], NONE, "prints a line on standard output"),
    f("", "plot", &["plot(csv, x, [ys], file)"], NONE, "a line plot of columns of a CSV of the output folder: SVG, or PNG when `file` ends in .png"),
    f("", "plot_field", &["plot_field(csv, x, y, value, file)"], NONE, "a field over points: each row of a CSV of the output folder (write_points') a dot at (x, y) coloured by `value`, with a colour bar, axes at one scale: SVG, or PNG when `file` ends in .png"),
    f("", "exists", &["exists(file)"], NONE, "whether a file of the output folder exists (a checkpoint to resume from, or its previous copy)"),
    f("", "read_column", &["read_column(csv, column)"], NONE, "a column of a CSV of the output folder (series.csv...) as an array of numbers"),
    f("", "load_plugin", &["load_plugin(path)", "load_plugin(path, #{ replace })"], &["replace"], "loads a native constitutive-law plugin (a .so) and returns its law's name; its code runs with your rights: load only libraries you trust. A law of a name already registered (built in, another library's) is refused unless `replace: true`; the same library loaded again is a no-op"),
    f("", "mpm", &["mpm(#{ dim, origin, cell, cells, velocity_update })"], &["dim", "origin", "cell", "cells", "velocity_update"], "a new MPM simulation on a regular mesh: `cell` a size or one per axis, `cells` a count per axis"),
    f("", "mpm_load", &["mpm_load(path)"], NONE, "an MPM simulation from a checkpoint written by `sim.save` (path from the working directory)"),
    f("", "dem", &["dem()", "dem(#{ seed, skin })"], &["seed", "skin"], "a new DEM simulation; the Verlet skin defaults to half the smallest radius"),
    f("", "element_test", &["element_test(law, #{ ...law parameters }, #{ stress, strain, hold, steps })"], &["stress", "strain", "hold", "steps"], "drives a law on one point without a mesh: from `stress`, the `strain` increment [xx, yy, zz, xy, yz, xz] in `steps` equal parts, the components of `hold` (#{ xx: -1e5 }) kept at those stresses; returns #{ stress, strain, p, q, state } per step"),
    f("", "load_mesh", &["load_mesh(path)"], NONE, "a gmsh mesh (MSH 4.1 or 2.2, ASCII or binary) with its physical groups, for `fill_mesh`, `fix`, `friction` and `traction` (path from the working directory or the script's folder)"),
    f("", "dem_load", &["dem_load(path)"], NONE, "a DEM simulation from a state written by `sim.save` (path from the working directory)"),
    // Rhai's functions that allocate what they are asked in one call, checked first against the
    // memory the process can take.
    f("array", "pad", &["array.pad(length, value)"], NONE, "Rhai's: fills the array up to `length` with `value`; refused beyond the memory this process can take"),
    f("string", "pad", &["string.pad(length, character)", "string.pad(length, text)"], NONE, "Rhai's: fills the string up to `length` characters; refused beyond the memory this process can take"),
    f("blob", "pad", &["blob.pad(length, byte)"], NONE, "Rhai's: fills the BLOB up to `length` bytes; refused beyond the memory this process can take"),
    f("", "blob", &["blob(length)", "blob(length, byte)"], NONE, "Rhai's: a BLOB of `length` bytes (0 or `byte`); refused beyond the memory this process can take"),
    // Both simulations: running and output.
    f("sim", "run", &["sim.run()", "sim.run(steps)"], NONE, "runs in the background (until paused, or for `steps`) and returns at once"),
    f("sim", "run_steps", &["sim.run_steps(steps)"], NONE, "runs `steps` steps at the prompt (Ctrl-C pauses)"),
    f("sim", "run_until", &["sim.run_until(time)"], NONE, "runs until the simulated time reaches `time` (s)"),
    f("sim", "step", &["sim.step()", "sim.step"], NONE, "one step; as a property, the number of steps done"),
    f("sim", "pause", &["sim.pause()"], NONE, "stops a background run after the step under way"),
    f("sim", "wait", &["sim.wait()"], NONE, "waits for a background run to end; passes on its error"),
    f("sim", "running", &["sim.running"], NONE, "whether a background run goes on"),
    f("sim", "every", &["sim.every(steps, |sim| ...)"], NONE, "calls a function every `steps` steps of a run"),
    f("sim", "series_every", &["sim.series_every(steps)"], NONE, "a series.csv row every `steps` steps"),
    f("sim", "vtk_every", &["sim.vtk_every(steps)"], NONE, "a VTK frame every `steps` steps"),
    f("sim", "series_column", &["sim.series_column(name, |sim| value)"], NONE, "an extra series.csv column computed by a function; declare every column before the first run (series.csv's header fixes them)"),
    f("sim", "diagnostics", &["sim.diagnostics()"], NONE, "a map of global measures: energies, counts, unbalanced force..."),
    f("sim", "write_points", &["sim.write_points(file)"], NONE, "a CSV of every point or sphere in the output folder"),
    f("sim", "write_series", &["sim.write_series()"], NONE, "a series.csv row now"),
    f("sim", "write_vtk", &["sim.write_vtk()"], NONE, "a VTK frame now (DEM: spheres, walls and contact network)"),
    f("sim", "vtk_format", &["sim.vtk_format(\"binary\" | \"ascii\" | \"vtkhdf\")"], NONE, "where VTK frames go: one XML file a frame with zlib-compressed binary (default) or text arrays, or every frame in one vtk/run.vtkhdf (a build with --features vtkhdf)"),
    f("sim", "time", &["sim.time"], NONE, "simulated time, s"),
    f("sim", "dt", &["sim.dt(seconds)", "sim.dt"], NONE, "sets the time step; as a property, reads it"),
    f("sim", "critical_dt", &["sim.critical_dt()"], NONE, "the stability limit of the time step (MPM: P-wave cell crossing; DEM: sqrt(m/k_n) of one contact)"),
    f("sim", "gravity", &["sim.gravity([gx, gy, gz])"], NONE, "body acceleration, m/s^2"),
    f("sim", "damping", &["sim.damping(d)"], NONE, "Cundall local damping in [0, 1)"),
    f("sim", "checkpoint_every", &["sim.checkpoint_every(n, file)"], NONE, "a checkpoint (as sim.save) every n steps of the runs, overwritten, and one when a signal stops the run"),
    f("sim", "save", &["sim.save(file)"], NONE, "the whole state, to continue bit for bit (file in the output folder); returns the path"),
    // MPM.
    f("MpmSim", "material", &["sim.material(law, #{ density, name, ...law parameters })"], &["density", "name"], "a material of a registered law (`granite plugins` lists them and their parameters)"),
    f("MpmSim", "script_material", &["sim.script_material(name, |stress, dstrain, state| ..., #{ density, state })"], &["density", "state"], "a material whose law is a script function"),
    f("MpmSim", "set_material", &["sim.set_material(material, #{ ...law parameters })", "sim.set_material(\"name\", #{ ...law parameters })"], NONE, "new values of some law parameters from the next step on; points keep stress and state (a material by its handle or, in a simulation loaded with mpm_load, by its name)"),
    f("MpmSim", "memory_per_point", &["sim.memory_per_point(material)"], NONE, "bytes a point of this material holds (its law's object included)"),
    f("MpmSim", "fill_box", &["sim.fill_box(material, lower, upper)", "sim.fill_box(material, lower, upper, #{ per_cell, layout, velocity, stress })"], FILL, "material points in every cell of a box"),
    f("MpmSim", "fill_mesh", &["sim.fill_mesh(material, mesh, group)", "sim.fill_mesh(material, mesh, group, #{ per_cell, layout, velocity, stress })"], FILL, "material points in every cell of the background grid whose points lie in the surfaces (2D) or volumes (3D) of a physical group of a gmsh mesh; returns the count"),
    f("MpmSim", "fill_region", &["sim.fill_region(material, |x| bool, #{ per_cell, layout, velocity, stress })"], FILL, "material points where a function of the position is true"),
    f("MpmSim", "add_points", &["sim.add_points(material, [[x, y], ...], volume)"], NONE, "explicit material points"),
    f("MpmSim", "initial_stress", &["sim.initial_stress([sxx, syy, szz, sxy, syz, sxz])"], NONE, "a uniform stress on every point (tension positive)"),
    f("MpmSim", "geostatic_stress", &["sim.geostatic_stress(surface, k0)"], NONE, "vertical stress -rho g (surface - height), horizontal k0 times it"),
    f("MpmSim", "scheme", &["sim.scheme(\"USF\" | \"USL\" | \"MUSL\")"], NONE, "stress update scheme"),
    f("MpmSim", "shape_functions", &["sim.shape_functions(name)", "sim.shape_functions(\"gimp\", #{ point_size })"], &["point_size"], "\"linear\" (default), \"gimp\" (uGIMP; point_size in m, default from the points' mean volume), \"bspline2\" or \"bspline3\" (B-splines, open at the mesh edges)"),
    f("MpmSim", "volumetric_strain", &["sim.volumetric_strain(\"point\" | \"cell\")"], NONE, "where the volumetric part of a point's strain increment comes from: its own velocity gradient (default) or the centre of its cell (B-bar, linear shape functions: against volumetric locking in plastic flow without dilatancy)"),
    f("MpmSim", "stress_rate", &["sim.stress_rate(\"plain\" | \"jaumann\")"], NONE, "the stress rate the laws integrate: plain increments (the thesis, default) or Jaumann (the stress turned with the point's spin first)"),
    f("MpmSim", "velocity_update", &["sim.velocity_update(name)", "sim.velocity_update(name, #{ flip_ratio })", "sim.velocity_update(\"ASFLIP\", #{ alpha, beta_min, beta_max })"], &["flip_ratio", "alpha", "beta_min", "beta_max"], "PIC, FLIP, NFLIP, FLIPX, NFLIPX, APIC or ASFLIP (Fei et al. 2021); `granite plugins` lists their parameters"),
    f("MpmSim", "mesh", &["sim.mesh(#{ origin, cell, cells })"], MESH, "replaces the mesh; points stay, boundary conditions are cleared"),
    f("MpmSim", "on_leave", &["sim.on_leave(\"delete\" | \"stop\")"], NONE, "what happens to points leaving the mesh"),
    f("MpmSim", "fix", &["sim.fix(selector, axis)", "sim.fix(selector, axis, value)", "sim.fix(mesh, group, axis)", "sim.fix(mesh, group, axis, value)"], NONE, "zero (or prescribed: number, [[t, v], ...] table or |t| function) velocity of nodes along an axis: those of a face (\"x-\", ...), those a closure |x| selects, or those within half a cell of a curve (2D) or surface (3D) group of a gmsh mesh"),
    f("MpmSim", "friction", &["sim.friction(face, mu)", "sim.friction(mesh, group, mu)"], NONE, "Coulomb friction on a face of the grid, or on the nodes within half a cell of a straight curve or plane surface group of a gmsh mesh normal to a grid axis (outward: away from the grid's middle)"),
    f("MpmSim", "traction", &["sim.traction(face, [tx, ty])", "sim.traction(face, t, factor)", "sim.traction(mesh, group, t)", "sim.traction(mesh, group, t, factor)"], NONE, "a uniform traction (Pa) on a face of the grid or on a curve (2D) or surface (3D) group of a gmsh mesh, as the nodal forces of eq. 3.22 (integrated exactly with the grid's shape functions); the nodes stay where they are as the material moves: for a load that follows it, point_traction"),
    f("MpmSim", "point_traction", &["sim.point_traction(mesh, group, t)", "sim.point_traction(mesh, group, t, factor)", "sim.point_traction(lower, upper, t)", "sim.point_traction(lower, upper, t, factor)"], NONE, "a traction (Pa) carried by the material points under a curve (2D) or surface (3D) group of a gmsh mesh (those within their own size of it; the whole load is t times the group's measure), or by the points in a box (each over its surface share V^((d-1)/d)); mapped to the nodes through the points' shape functions every step, it follows the material (CB-Geo's particle traction); `factor` as for `traction`"),
    f("MpmSim", "point_pressure", &["sim.point_pressure(mesh, group, p)", "sim.point_pressure(mesh, group, p, factor)"], NONE, "a pressure (Pa, > 0 pushes in) carried by the material points under a curve or surface group, each piece of the group pushing along its inward normal with p times its measure"),
    f("MpmSim", "nodal_force", &["sim.nodal_force(selector, [fx, fy])", "sim.nodal_force(selector, f, factor)"], NONE, "the same force on each selected node"),
    f("MpmSim", "track_runout", &["sim.track_runout(width0, height0)"], NONE, "runout columns in the series from now (thesis 5.6-5.9)"),
    f("MpmSim", "points", &["sim.points"], NONE, "number of material points"),
    f("MpmSim", "point_stress", &["sim.point_stress(i)"], NONE, "stress of point i, [sxx, syy, szz, sxy, syz, sxz], tension positive"),
    f("MpmSim", "point_strain", &["sim.point_strain(i)"], NONE, "strain of point i"),
    f("MpmSim", "point_state", &["sim.point_state(i, name)"], NONE, "a state variable of point i's law"),
    f("MpmSim", "point_velocity", &["sim.point_velocity(i)"], NONE, "velocity of point i, m/s"),
    f("MpmSim", "set_point_velocity", &["sim.set_point_velocity(i, [vx, vy])"], NONE, "sets the velocity of point i (an initial velocity field, say)"),
    f("MpmSim", "point_position", &["sim.point_position(i)"], NONE, "position of point i"),
    f("MpmSim", "balance_every", &["sim.balance_every(n)"], NONE, "steps between two balances of the RVEs over MPI processes by their measured cost (default 50; 0: never)"),
    f("MpmSim", "write_point_object", &["sim.write_point_object(i, file)"], NONE, "a VTU of point i's own object (the RVE of dem_rve)"),
    f("Material", "name", &["material.name"], NONE, "the material's name"),
    f("Mesh", "groups", &["mesh.groups()"], NONE, "the mesh's physical groups: #{ name, dim, elements } each"),
    f("Mesh", "measure", &["mesh.measure(group)"], NONE, "length, area or volume of a physical group"),
    // DEM: set-up.
    f("DemSim", "material", &["sim.material(#{ name, density, young, poisson, rigid })"], &["name", "density", "young", "poisson", "rigid"], "a DEM material; `young` and `poisson` (or `rigid: true`) serve laws that combine two materials"),
    f("DemSim", "set_material", &["sim.set_material(material, #{ young, poisson, rigid })"], &["young", "poisson", "rigid"], "new moduli of a material, reaching existing contacts at the next step"),
    f("DemSim", "contact_law", &["sim.contact_law(law, #{ ...parameters })", "sim.contact_law(law, material1, material2, #{ ...parameters })"], NONE, "the default contact law, or that of one material pair; existing contacts keep their history"),
    f("DemSim", "contact_law_params", &["sim.contact_law_params()", "sim.contact_law_params(material1, material2)"], NONE, "the law in force and its parameters"),
    f("DemSim", "set_contact_params", &["sim.set_contact_params(#{ ...parameters })", "sim.set_contact_params(material, #{ ...parameters })", "sim.set_contact_params(material1, material2, #{ ...parameters })"], NONE, "changes some parameters of the default law, of every pair one material is in, or of one pair, from the next step on, keeping every contact and its history"),
    f("DemSim", "sphere", &["sim.sphere(material, [x, y, z], radius)", "sim.sphere(material, [x, y, z], radius, #{ velocity, fixed })"], &["velocity", "fixed"], "one sphere; returns its id"),
    f("DemSim", "cloud", &["sim.cloud(material, lower, upper, #{ count, radius, psd, seed })"], &["count", "radius", "psd", "seed"], "random non-overlapping spheres in a box"),
    f("DemSim", "allow_overlaps", &["sim.allow_overlaps(true)"], NONE, "no warning for bodies overlapping by more than 10 % of a radius at the start of a run"),
    f("DemSim", "lattice", &["sim.lattice(material, lower, upper, #{ spacing, radius, jitter, seed })"], &["spacing", "radius", "jitter", "seed"], "spheres on a cubic lattice"),
    f("DemSim", "clump", &["sim.clump(material, [[x, y, z, r], ...])"], NONE, "a rigid clump of spheres"),
    f("DemSim", "tetra_clump", &["sim.tetra_clump(material, centre, r_sphere, r_clump)"], NONE, "a clump of four spheres on a tetrahedron (thesis table 2.3)"),
    f("DemSim", "clump_cloud", &["sim.clump_cloud(material, lower, upper, #{ count, shape, seed, ...shape parameters })"], &["count", "shape", "seed"], "random grains of a registered shape model (spheres and clumps: `sphere`, `tetra`) or body kind (`capsule`, `potential_tetra`, `potential_box`, with its parameters), random orientations, clear of the bounding spheres of what is there already"),
    f("DemSim", "potential", &["sim.potential(material, centre, #{ shape, ...shape parameters, rotation, velocity, spin, fixed })", "sim.potential(material, centre, #{ planes: [[a, b, c, d], ...], r, R, k, rotation, velocity, spin, fixed })"], &["shape", "planes", "r", "R", "k", "rotation", "velocity", "spin", "fixed"], "one potential particle (thesis eq. 2.1), a body of the `potential` family: of a kind (`potential_tetra`, `potential_box`) or of its own planes a x + b y + c z = d (kind `potential`), centred at its centre of mass, turned by a rotation vector (rad); `fixed` moves only with its own velocity (a container part); it meets spheres, plane walls and other potential particles; returns its id"),
    f("DemSim", "potential_velocity", &["sim.potential_velocity(id, [vx, vy, vz])"], NONE, "sets a potential particle's velocity (a fixed one keeps it: a moving container part)"),
    f("DemSim", "potential_body", &["sim.potential_body(id)"], NONE, "a potential particle: #{ id, position, rotation (vector, rad), velocity, spin, force, torque (last step's contacts), mass, volume, fixed }"),
    f("DemSim", "potential_ids", &["sim.potential_ids()"], NONE, "the ids of the potential particles, in their order"),
    f("DemSim", "potentials", &["sim.potentials"], NONE, "the number of potential particles"),
    f("DemSim", "add_body", &["sim.add_body(kind, material, centre, #{ ...kind parameters, axis, rotation, velocity, spin, fixed })"], &["axis", "rotation", "velocity", "spin", "fixed"], "one body of a registered body kind (`granite plugins` lists them: capsule, potential_tetra, potential_box, potential), centred at its centre of mass, its body z axis along `axis` or turned by a rotation vector (rad); `fixed` moves only with its own velocity and spin; returns its id. Bodies meet spheres, plane walls and bodies of their family with the materials' contact laws"),
    f("DemSim", "capsule", &["sim.capsule(material, centre, #{ radius, length, axis, rotation, velocity, spin, fixed })"], &["radius", "length", "axis", "rotation", "velocity", "spin", "fixed"], "one capsule (a cylinder of `length` with hemispherical caps of `radius`, its axis along `axis`): sim.add_body(\"capsule\", ...)"),
    f("DemSim", "body_state", &["sim.body_state(id)"], NONE, "a body: #{ id, kind (its family), position, rotation (vector, rad), axis, velocity, spin, force, torque (last step's contacts), mass, volume, fixed }"),
    f("DemSim", "body_velocity", &["sim.body_velocity(id, [vx, vy, vz])"], NONE, "sets a body's velocity (a fixed one keeps it: a moving container part)"),
    f("DemSim", "body_spin", &["sim.body_spin(id, [wx, wy, wz])"], NONE, "sets a body's angular velocity, rad/s (a fixed one keeps it: a turning blade)"),
    f("DemSim", "body_contacts", &["sim.body_contacts(id)"], NONE, "a body's touching contacts (last step), seen from it: #{ with: \"body\" | \"wall\" | \"sphere\", id (the other body's or sphere's id, the wall's index), kind (the other body's kind, the wall's name, \"sphere\"), force (on this body), and the keys of `contacts()` }"),
    f("DemSim", "body_ids", &["sim.body_ids()"], NONE, "the ids of the bodies of plugin kinds, in their order"),
    f("DemSim", "bodies", &["sim.bodies"], NONE, "the number of bodies of plugin kinds"),
    f("DemSim", "wall_plane", &["sim.wall_plane(material, point, normal)"], NONE, "an infinite plane wall; returns the wall (a DemWall, which other simulations refuse)"),
    f("DemSim", "wall_rect", &["sim.wall_rect(material, centre, u, v, [half_u, half_v])"], NONE, "a rectangular wall"),
    f("DemSim", "wall_disk", &["sim.wall_disk(material, centre, normal, radius)"], NONE, "a disk wall"),
    f("DemSim", "wall_cylinder", &["sim.wall_cylinder(material, base, axis, radius, length)"], NONE, "a cylindrical shell wall"),
    f("DemSim", "box_walls", &["sim.box_walls(material, lower, upper)", "sim.box_walls(material, lower, upper, #{ open_top })"], &["open_top"], "six (or five) plane walls around a box (x-, x+, y-, y+, z-, z+); returns the array of their walls"),
    f("DemSim", "wall_mesh", &["sim.wall_mesh(material, file_or_mesh)", "sim.wall_mesh(material, file_or_mesh, #{ group, scale, translate, rotate })"], &["group", "scale", "translate", "rotate"], "walls of the triangles of an STL file (ASCII or binary), or of a surface `group` of a gmsh file or of a mesh from load_mesh; each point scaled, turned by the rotation vector `rotate` (rad) and moved by `translate`; touched from both sides on faces, edges and corners (a shared edge or corner counted once); returns the array of their walls, which the other wall calls take as one wall"),
    f("DemSim", "wall_velocity", &["sim.wall_velocity(wall, [vx, vy, vz])", "sim.wall_velocity(wall, axis, |t| v)"], NONE, "moves a wall (a wall this simulation made or its index, or an array of them moving together)"),
    f("DemSim", "wall_spin", &["sim.wall_spin(wall, [wx, wy, wz], pivot)"], NONE, "turns walls of a wall mesh (an array from wall_mesh) at an angular velocity (rad/s) about a pivot point, which moves with the walls' velocity; contacts feel the surface's velocity there"),
    f("DemSim", "wall_force", &["sim.wall_force(wall)"], NONE, "the force the spheres and bodies exerted on a wall (or an array of walls: their sum) in the last step"),
    f("DemSim", "wall_torque", &["sim.wall_torque(wall, point)"], NONE, "the torque about `point` of the forces the spheres and bodies exerted on a wall (or an array of walls) in the last step, at their contact points"),
    f("DemSim", "wall_position", &["sim.wall_position(wall)"], NONE, "where a wall is (of an array: its first wall's reference point, a mesh's first corner)"),
    f("DemSim", "skin", &["sim.skin(distance)", "sim.skin"], NONE, "the Verlet skin of the candidate lists"),
    f("DemSim", "stable_dt", &["sim.stable_dt()"], NONE, "a time step below the stability limit of the present contacts"),
    f("DemSim", "stop_on_unstable_dt", &["sim.stop_on_unstable_dt(on)"], NONE, "whether a time step proved unstable stops the run (default true)"),
    f("DemSim", "erase_outside", &["sim.erase_outside(lower, upper)"], NONE, "erases the particles outside a box; returns how many"),
    f("DemSim", "particles", &["sim.particles"], NONE, "number of spheres"),
    f("DemSim", "clumps", &["sim.clumps"], NONE, "number of clumps"),
    f("DemSim", "memory_bytes", &["sim.memory_bytes"], NONE, "memory held by the scene's arrays"),
    // DEM: bodies and contacts.
    f("DemSim", "body", &["sim.body(id)"], NONE, "one sphere: position, velocity, spin, force, torque, mass, radius, material, clump, fixed..."),
    f("DemSim", "set_body", &["sim.set_body(id, #{ position, velocity, spin, radius, material, mass, fixed, force, torque })"], &["position", "velocity", "spin", "radius", "material", "mass", "fixed", "force", "torque"], "changes one sphere between steps; force and torque are lasting external loads"),
    f("DemSim", "erase", &["sim.erase(id)", "sim.erase([ids])"], NONE, "erases spheres (a clump member takes its clump); other contacts keep their history"),
    f("DemSim", "ids", &["sim.ids()"], NONE, "the spheres' ids, in the order of the bulk arrays"),
    f("DemSim", "positions", &["sim.positions()"], NONE, "every sphere's position"),
    f("DemSim", "velocities", &["sim.velocities()"], NONE, "every sphere's velocity"),
    f("DemSim", "spins", &["sim.spins()"], NONE, "every sphere's angular velocity"),
    f("DemSim", "forces", &["sim.forces()"], NONE, "every sphere's force of the last step"),
    f("DemSim", "torques", &["sim.torques()"], NONE, "every sphere's torque of the last step"),
    f("DemSim", "radii", &["sim.radii()"], NONE, "every sphere's radius"),
    f("DemSim", "contact_counts", &["sim.contact_counts()"], NONE, "every sphere's number of touching contacts"),
    f("DemSim", "contacts", &["sim.contacts()"], NONE, "every touching contact, of spheres, bodies and walls: id1, kind1, id2, kind2 (or wall), part (a body's contact point), point, normal, overlap, force, normal_force, shear_force, law, params"),
    f("DemSim", "contact", &["sim.contact(id1, id2)"], NONE, "the contact of two spheres, or ()"),
    f("DemSim", "wall_contact", &["sim.wall_contact(id, wall)"], NONE, "the contact of a sphere with a wall, or ()"),
    f("DemSim", "track_energy", &["sim.track_energy(on)"], NONE, "tracks the energy balance from the next step on (series columns energy_*)"),
    f("DemSim", "energy", &["sim.energy()"], NONE, "kinetic, gravitational, elastic, friction, viscous, damping, boundary_work, total, initial_total (J)"),
    f("DemSim", "fabric", &["sim.fabric()"], NONE, "fabric tensor (1/N) sum n n of the sphere contacts"),
    // DEM: periodic cell and measures.
    f("DemSim", "periodic", &["sim.periodic([lx, ly, lz])"], NONE, "makes the domain a periodic cell"),
    f("DemSim", "cell_velocity_gradient", &["sim.cell_velocity_gradient([[Lxx, Lxy, Lxz], ...])"], NONE, "a prescribed velocity gradient of the cell"),
    f("DemSim", "cell_update", &["sim.cell_update(\"sllod\" | \"newton\" | \"yade\")", "sim.cell_update()"], NONE, "how the particles' fluctuations follow the cell's field L x: SLLOD's v -= L v dt (default, the same for a particle and its images), Newton's law for the whole velocity (YADE's homoDeform 1), or the forces alone (YADE's default homoDeform 2)"),
    f("DemSim", "cell_control", &["sim.cell_control(#{ x: #{ stress, max_rate } or #{ rate }, y, z, xy, ..., relax_steps })"], &["x", "y", "z", "xy", "xz", "yz", "yx", "zx", "zy", "relax_steps"], "stress (a proportional-integral servo closing an error in about relax_steps steps, default 200) or strain-rate control of the cell per axis"),
    f("DemSim", "cell_stress", &["sim.cell_stress()"], NONE, "Love-Weber stress of the cell"),
    f("DemSim", "stress_reached", &["sim.stress_reached(tolerance)"], NONE, "whether the controlled stresses are within a relative tolerance"),
    f("DemSim", "cell_size", &["sim.cell_size()"], NONE, "lengths of the cell's base vectors"),
    f("DemSim", "cell_volume", &["sim.cell_volume()"], NONE, "volume of the cell"),
    f("DemSim", "cell_strain", &["sim.cell_strain()"], NONE, "logarithmic strains of the cell since its reference"),
    f("DemSim", "reset_cell_strain", &["sim.reset_cell_strain()"], NONE, "makes the present cell the strains' reference"),
    f("DemSim", "void_ratio", &["sim.void_ratio()"], NONE, "void ratio of the periodic cell"),
    f("DemSim", "love_weber_stress", &["sim.love_weber_stress(volume)"], NONE, "Love-Weber stress of the contacts over a volume"),
    f("DemSim", "global_stress", &["sim.global_stress(volume)"], NONE, "stress from walls and gravity (thesis appendix A)"),
    f("DemSim", "angle_of_repose", &["sim.angle_of_repose(#{ heap, x_range, y_range, open_x, centre, radius, z_range, d, x_min, x_max })"], &["heap", "x_range", "y_range", "open_x", "centre", "radius", "z_range", "d", "x_min", "x_max"], "angle of repose of a heap (thesis 2.3.2)"),
    f("DemSim", "void_ratio_sub_volume", &["sim.void_ratio_sub_volume(#{ c, n_mc, shape, seed })"], &["c", "n_mc", "shape", "seed"], "void ratio in a homothetic sub-volume (thesis 2.3.3)"),
    f("DemSim", "void_ratio_tetrahedra", &["sim.void_ratio_tetrahedra(#{ n_mc, seed })"], &["n_mc", "seed"], "void ratio from a Delaunay tetrahedralisation (thesis 2.3.3)"),
    f("DemSim", "void_ratio_bounding_box", &["sim.void_ratio_bounding_box()"], NONE, "void ratio of the particles' bounding box"),
    f("DemMaterial", "name", &["material.name"], NONE, "the material's name"),
    f("DemWall", "index", &["wall.index"], NONE, "the wall's index among its simulation's walls (what `body_contacts`, `wall_contact` and messages name)"),
];

/// The option keys a function accepts, from the table (empty for an unknown function).
pub fn options_of(on: &str, name: &str) -> &'static [&'static str] {
    API.iter()
        .find(|d| d.name == name && (d.on == on || (d.on == "sim" && on.ends_with("Sim"))))
        .map_or(NONE, |d| d.options)
}

/// Entries for a name as a user types it: `sphere`, `sim.sphere`, `DemSim.sphere`.
pub fn lookup(query: &str) -> Vec<&'static ApiDoc> {
    let (on, name) = match query.rsplit_once('.') {
        Some((on, name)) => (Some(on), name),
        None => (None, query),
    };
    API.iter()
        .filter(|d| d.name == name)
        .filter(|d| match on {
            None | Some("sim") => true,
            Some(on) => d.on == on || (d.on == "sim" && on.ends_with("Sim")),
        })
        .collect()
}

/// What `:help NAME` prints for one entry.
pub fn help_text(d: &ApiDoc) -> String {
    let on = match d.on {
        "" => "global function".to_string(),
        "sim" => "MpmSim and DemSim".to_string(),
        other => other.to_string(),
    };
    let mut out = format!("{} ({on}): {}\n", d.name, d.doc);
    for form in d.forms {
        out.push_str(&format!("  {form}\n"));
    }
    if !d.options.is_empty() {
        out.push_str(&format!("  options: {}\n", d.options.join(", ")));
    }
    out
}

/// Levenshtein distance, for "did you mean".
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut previous = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let here = row[j + 1];
            row[j + 1] = (previous + usize::from(ca != cb)).min(row[j] + 1).min(here + 1);
            previous = here;
        }
    }
    row[b.len()]
}

/// The candidates closest to `word` (at most about a third of its letters wrong: two swapped
/// letters count two), the closest ones only.
pub fn closest<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Vec<&'a str> {
    let limit = word.chars().count().div_ceil(3);
    let mut scored: Vec<(usize, &str)> =
        candidates.into_iter().map(|c| (distance(word, c), c)).filter(|(d, _)| *d <= limit).collect();
    scored.sort();
    scored.dedup_by(|a, b| a.1 == b.1);
    let best = scored.first().map_or(0, |s| s.0);
    scored.into_iter().take_while(|s| s.0 == best).map(|s| s.1).collect()
}

/// "did you mean" for a misspelt function or method name (empty when nothing is close).
pub fn did_you_mean(name: &str) -> String {
    let names = API.iter().map(|d| d.name);
    let found = closest(name, names);
    match found.as_slice() {
        [] => String::new(),
        [one] => format!("; did you mean `{one}`?"),
        many => {
            format!("; did you mean one of {}?", many.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", "))
        }
    }
}

/// The API as a Markdown reference (docs/api.md).
pub fn markdown() -> String {
    let mut out = String::from(
        "# Script API reference\n\nGenerated from the table the REPL's `:help` reads \
         (`scripting/src/api_doc.rs`); regenerate with `granite api > docs/api.md`.\n\
         `sim` is an `MpmSim` or a `DemSim`; `#{ ... }` is an options map whose keys are listed.\n",
    );
    let sections = [
        ("", "Global functions"),
        ("sim", "Both simulations"),
        ("MpmSim", "MPM simulations (`mpm(...)`)"),
        ("Material", "MPM materials"),
        ("Mesh", "gmsh meshes (`load_mesh(...)`)"),
        ("DemSim", "DEM simulations (`dem(...)`)"),
        ("DemMaterial", "DEM materials"),
        ("DemWall", "DEM walls (`wall_plane`, `box_walls`, `wall_mesh`, ...)"),
        ("array", "Rhai's arrays"),
        ("string", "Rhai's strings"),
        ("blob", "Rhai's BLOBs"),
    ];
    for (on, title) in sections {
        out.push_str(&format!("\n## {title}\n\n| call | options | what it does |\n|---|---|---|\n"));
        for d in API.iter().filter(|d| d.on == on) {
            let forms = d.forms.iter().map(|f| format!("`{}`", f.replace('|', "\\|"))).collect::<Vec<_>>().join("<br>");
            out.push_str(&format!("| {forms} | {} | {} |\n", d.options.join(", "), d.doc.replace('|', "\\|")));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_names_are_suggested() {
        assert_eq!(closest("gravty", ["gravity", "damping", "grain"]), vec!["gravity"]);
        assert!(closest("xyz", ["gravity"]).is_empty());
        assert!(did_you_mean("gravty").contains("`gravity`"));
    }

    #[test]
    fn names_look_up_with_or_without_receiver() {
        assert_eq!(lookup("sphere").len(), 1);
        assert_eq!(lookup("DemSim.sphere").len(), 1);
        assert_eq!(lookup("sim.material").len(), 2);
        assert_eq!(lookup("MpmSim.run").len(), 1);
        assert!(lookup("MpmSim.sphere").is_empty());
    }
}

fn is_word(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Tab completion of `line` up to `pos`: where the word being typed starts and what it may
/// become. After `x.` the methods of `x`'s type (from `variables`, name and type), inside an
/// options map `#{ ... }` given to a call the keys that call accepts, elsewhere global functions
/// and variables.
pub fn complete(line: &str, pos: usize, variables: &[(String, String)]) -> (usize, Vec<String>) {
    let before = &line[..pos.min(line.len())];
    let start = before.rfind(|c: char| !is_word(c)).map_or(0, |i| i + 1);
    let word = &before[start..];
    let mut found: Vec<String> = Vec::new();
    let head = &before[..start];
    if let Some(receiver_end) = head.strip_suffix('.') {
        let receiver_start = receiver_end.rfind(|c: char| !is_word(c)).map_or(0, |i| i + 1);
        let receiver = &receiver_end[receiver_start..];
        let on = variables.iter().find(|(name, _)| name == receiver).map(|(_, ty)| ty.as_str());
        for d in API.iter().filter(|d| !d.on.is_empty()) {
            let fits = match on {
                Some(ty) => d.on == ty || (d.on == "sim" && ty.ends_with("Sim")),
                None => true,
            };
            if fits {
                found.push(d.name.to_string());
            }
        }
    } else if let Some((on, name)) = open_options_call(head, variables) {
        found.extend(options_of(&on, &name).iter().map(|k| k.to_string()));
    } else {
        found.extend(API.iter().filter(|d| d.on.is_empty()).map(|d| d.name.to_string()));
        found.extend(variables.iter().map(|(name, _)| name.clone()));
    }
    found.retain(|c| c.starts_with(word));
    found.sort();
    found.dedup();
    (start, found)
}

/// The call whose options map is open at the end of `text` (`sim.cloud(m, a, b, #{ count: 3, `):
/// the receiver's type (or "" for a global function) and the function's name.
fn open_options_call(text: &str, variables: &[(String, String)]) -> Option<(String, String)> {
    let map_at = text.rfind("#{")?;
    // The map is still open: no `}` closes it before the end.
    let mut depth = 0i32;
    for c in text[map_at + 2..].chars() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => return None,
            '}' => depth -= 1,
            _ => {}
        }
    }
    // The innermost call still open before the map.
    let mut depth = 0i32;
    let mut paren = None;
    for (i, c) in text[..map_at].char_indices().rev() {
        match c {
            ')' => depth += 1,
            '(' if depth == 0 => {
                paren = Some(i);
                break;
            }
            '(' => depth -= 1,
            _ => {}
        }
    }
    let callee = text[..paren?].trim_end();
    let name_start = callee.rfind(|c: char| !is_word(c)).map_or(0, |i| i + 1);
    let name = &callee[name_start..];
    let on = match callee[..name_start].strip_suffix('.') {
        Some(receiver_end) => {
            let receiver_start = receiver_end.rfind(|c: char| !is_word(c)).map_or(0, |i| i + 1);
            let receiver = &receiver_end[receiver_start..];
            variables.iter().find(|(n, _)| n == receiver).map(|(_, ty)| ty.clone()).unwrap_or_else(|| {
                // An unknown receiver: the first type that has this function with options.
                API.iter().find(|d| d.name == name && !d.options.is_empty()).map_or(String::new(), |d| d.on.to_string())
            })
        }
        None => String::new(),
    };
    Some((on, name.to_string()))
}

#[cfg(test)]
mod completion_tests {
    use super::complete;

    fn vars() -> Vec<(String, String)> {
        vec![
            ("sim".into(), "DemSim".into()),
            ("mpm_sim".into(), "MpmSim".into()),
            ("glass".into(), "DemMaterial".into()),
        ]
    }

    #[test]
    fn methods_of_the_variables_type() {
        let (start, found) = complete("sim.gra", 7, &vars());
        assert_eq!((start, found), (4, vec!["gravity".to_string()]));
        let (_, found) = complete("sim.wall_", 9, &vars());
        assert!(found.contains(&"wall_plane".to_string()) && found.contains(&"wall_velocity".to_string()));
        // fill_box is an MpmSim method, not a DemSim one.
        assert!(complete("sim.fill", 8, &vars()).1.is_empty());
        assert_eq!(complete("mpm_sim.fill", 12, &vars()).1, vec!["fill_box", "fill_mesh", "fill_region"]);
    }

    #[test]
    fn option_keys_of_the_open_call() {
        let line = "sim.cloud(glass, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], #{ count: 10, ra";
        assert_eq!(complete(line, line.len(), &vars()).1, vec!["radius"]);
        let line = "let s = dem(#{ se";
        assert_eq!(complete(line, line.len(), &vars()).1, vec!["seed"]);
        // A closed map completes functions and variables again.
        let line = "sim.cloud(glass, a, b, #{ count: 1 }); gl";
        assert_eq!(complete(line, line.len(), &vars()).1, vec!["glass"]);
    }

    #[test]
    fn global_functions_and_variables() {
        assert_eq!(complete("dem_l", 5, &vars()).1, vec!["dem_load"]);
        assert_eq!(complete("mp", 2, &vars()).1, vec!["mpm", "mpm_load", "mpm_sim"]);
    }
}
