//! gmsh meshes in scripts: `load_mesh(path)`, `mesh.groups()`, and the MPM calls that take a
//! mesh group: `sim.fill_mesh`, `sim.fix`, `sim.friction`, `sim.traction` (see docs/mpm.md,
//! "Geometry from gmsh").

use super::convert::{err, number, vector, OrRhai, RhaiResult};
use super::mpm_api::{MaterialHandle, Region, SimHandle};
use super::ScriptContext;
use granite_core::error::GraniteError;
use granite_core::io::gmsh::GmshMesh;
use granite_core::mpm::boundary::{nodes_near, traction_on_simplices, FrictionConstraint};
use granite_core::region::Simplices;
use rhai::{Array, Dynamic, Engine, Map};
use std::sync::Arc;

/// A mesh read by `load_mesh`, shared by the calls that use it.
#[derive(Clone)]
pub struct MeshHandle {
    pub file: String,
    pub mesh: Arc<GmshMesh>,
}

impl MeshHandle {
    /// The simplices of `group`, checked to be of dimension `want` (given in words for the
    /// error) in a simulation of dimension `space`.
    fn group(&self, name: &str, space: usize, want: usize, call: &str) -> RhaiResult<Simplices> {
        let g = self.mesh.group(name).or_rhai()?;
        let dim = self.mesh.groups[g].dim as usize;
        if dim != want {
            let what = |d: usize| match d {
                0 => "points",
                1 => "curves",
                2 => "surfaces",
                _ => "volumes",
            };
            return err(format!(
                "sim.{call}(mesh, \"{name}\", ...): group \"{name}\" of {} holds {} ({dim}D); a {space}D simulation takes {} here",
                self.file,
                what(dim),
                what(want)
            ));
        }
        Simplices::of_group(&self.mesh, g, space).or_rhai()
    }

    fn describe(&self) -> String {
        format!(
            "Mesh(\"{}\", {} nodes, {} elements, {} groups)",
            self.file,
            self.mesh.nodes.len(),
            self.mesh.elements.len(),
            self.mesh.groups.len()
        )
    }
}

/// The triangles of a surface for `wall_mesh`, and a name for its walls: an STL file, or the
/// surface `group` of a gmsh file or of a loaded mesh.
pub(super) fn surface_triangles(
    script: &ScriptContext,
    source: Dynamic,
    group: Option<&str>,
) -> RhaiResult<(String, Vec<[granite_core::math::Vec3; 3]>)> {
    let from_group = |handle: &MeshHandle| -> RhaiResult<(String, Vec<[granite_core::math::Vec3; 3]>)> {
        let Some(group) = group else {
            return err(format!(
                "wall_mesh: a gmsh mesh ({}) needs the surface group: #{{ group: \"...\" }}",
                handle.file
            ));
        };
        let simplices = handle.group(group, 3, 2, "wall_mesh")?;
        Ok((group.to_string(), simplices.corners.iter().map(|c| [c[0], c[1], c[2]]).collect()))
    };
    if let Some(m) = source.clone().try_cast::<MeshHandle>() {
        return from_group(&m);
    }
    let Ok(file) = source.clone().into_string() else {
        return err(format!(
            "wall_mesh takes an STL or gmsh file name or a mesh from load_mesh, got {}",
            source.type_name()
        ));
    };
    let path = script
        .input_path(&file)
        .map_err(|why| super::convert::to_rhai(GraniteError::Setup(format!("wall_mesh: {why}"))))?;
    let stem = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
    if file.to_ascii_lowercase().ends_with(".msh") {
        return from_group(&MeshHandle { file: file.clone(), mesh: Arc::new(GmshMesh::read(&path).or_rhai()?) });
    }
    if group.is_some() {
        return err(format!("wall_mesh: `group` names a surface of a gmsh mesh; {file} is read as STL"));
    }
    Ok((stem, granite_core::io::stl::read_stl(&path).or_rhai()?))
}

/// The grid nodes of a curve (2D) or surface (3D) group: those within half the smallest cell.
fn boundary_nodes(s: &SimHandle, mesh: &MeshHandle, group: &str, call: &str) -> RhaiResult<(Vec<u32>, Simplices)> {
    let grid = s.lock().sim.mpm.mesh.clone();
    let simplices = mesh.group(group, grid.dim, grid.dim - 1, call)?;
    let nodes = nodes_near(&grid, &simplices, 0.5 * grid.min_cell());
    if nodes.is_empty() {
        return err(format!(
            "sim.{call}(mesh, \"{group}\", ...): no grid node lies within half a cell of the group: does it lie inside the background mesh?"
        ));
    }
    Ok((nodes, simplices))
}

fn fill_mesh(s: &mut SimHandle, m: &MaterialHandle, mesh: &MeshHandle, group: &str, opts: Map) -> RhaiResult<i64> {
    let dim = s.lock().sim.mpm.dim();
    let simplices = mesh.group(group, dim, dim, "fill_mesh")?;
    s.fill(None, m, Region::Mesh(simplices), opts)
}

fn friction(s: &mut SimHandle, mesh: &MeshHandle, group: &str, mu: Dynamic) -> RhaiResult<()> {
    let mu = number(&mu, "mu")?;
    if !(mu >= 0.0 && mu.is_finite()) {
        return err(format!("friction coefficient `mu` must be finite and >= 0, got {mu}"));
    }
    let (nodes, simplices) = boundary_nodes(s, mesh, group, "friction")?;
    let normal = simplices.mean_normal();
    let Some(axis) = (0..3).find(|&a| normal[a].abs() > 1.0 - 1e-9) else {
        return err(format!(
            "sim.friction(mesh, \"{group}\", mu): the group is not a straight boundary along a grid axis (mean normal {normal:?}); \
             friction acts on boundaries normal to x, y or z"
        ));
    };
    let mut st = s.lock();
    let grid = &st.sim.mpm.mesh;
    // Outward: from the grid's middle towards the group.
    let middle = 0.5 * (grid.origin[axis] + grid.upper()[axis]);
    let at = nodes.iter().map(|&n| grid.node_position(n as usize)[axis]).sum::<f64>() / nodes.len() as f64;
    let sign = if at < middle { -1.0 } else { 1.0 };
    st.sim.mpm.boundary.friction.push(FrictionConstraint { nodes, axis, sign, mu });
    Ok(())
}

fn traction(s: &mut SimHandle, mesh: &MeshHandle, group: &str, t: Dynamic, factor: Dynamic) -> RhaiResult<()> {
    let (nodes, forces) = {
        let st = s.lock();
        let grid = &st.sim.mpm.mesh;
        let simplices = mesh.group(group, grid.dim, grid.dim - 1, "traction")?;
        traction_on_simplices(grid, &simplices, vector(&t, grid.dim, "traction")?).or_rhai()?
    };
    s.add_force(nodes, forces, factor)
}

/// What a load carried by points pushes with: a traction vector, or a pressure on the surface's
/// outward normal.
enum Push {
    Traction(Dynamic),
    Pressure(Dynamic),
}

/// `sim.point_traction(mesh, group, t)` and `sim.point_pressure(mesh, group, p)`: the points
/// within their own size of a curve (2D) or surface (3D) group (the layer under it) carry the
/// load. Each segment or triangle of the group hands its length or area to the points nearest to
/// it, in proportion to their surface shares, so that each piece of the surface carries the
/// traction (or pressure) times its measure, and the whole load is the traction times the group's
/// measure. A pressure pushes along each piece's inward normal (the side its points are on).
fn point_load(s: &mut SimHandle, mesh: &MeshHandle, group: &str, push: Push, factor: Dynamic) -> RhaiResult<()> {
    use granite_core::math::{dot3, sub3};
    use granite_core::mpm::boundary::{point_size, surface_share, PointLoad, TimeFunction};
    let call = match push {
        Push::Traction(_) => "point_traction",
        Push::Pressure(_) => "point_pressure",
    };
    let (ids, forces) = {
        let st = s.lock();
        let sim = &st.sim.mpm;
        let dim = sim.dim();
        let simplices = mesh.group(group, dim, dim - 1, call)?;
        let pts = &sim.points;
        // (point, its share, its nearest piece of the surface)
        let mut carriers = Vec::new();
        for p in 0..pts.len() {
            if let Some((piece, _)) = simplices.nearest_within(pts.x[p], point_size(pts.volume[p], dim)) {
                carriers.push((p, surface_share(pts.volume[p], dim), piece));
            }
        }
        if carriers.is_empty() {
            return err(format!(
                "sim.{call}(mesh, \"{group}\", ...): no material point lies within its own size of the group: it \
                 must lie on the surface of the material (fill it first)"
            ));
        }
        let pieces = simplices.corners.len();
        // Per piece: the shares of its points, and which side they are on (points on the surface
        // itself count for neither side).
        let (mut shares, mut side) = (vec![0.0; pieces], vec![0.0; pieces]);
        for &(p, a, piece) in &carriers {
            shares[piece] += a;
            let (n, _) = simplices.normal_and_measure(piece);
            side[piece] += dot3(n, sub3(simplices.corner(piece), pts.x[p]));
        }
        // Pieces no point is nearest to hand their measure to all the others.
        let (mut held, mut whole) = (0.0, 0.0);
        for piece in 0..pieces {
            let (_, measure) = simplices.normal_and_measure(piece);
            whole += measure;
            if shares[piece] > 0.0 {
                held += measure;
            }
        }
        let spread = whole / held;
        let (traction, pressure) = match &push {
            Push::Traction(t) => (Some(vector(t, dim, "traction")?), 0.0),
            Push::Pressure(p) => (None, super::convert::finite(p, "pressure")?),
        };
        let forces: Vec<_> = carriers
            .iter()
            .map(|&(_, a, piece)| {
                let (n, measure) = simplices.normal_and_measure(piece);
                let area = a / shares[piece] * measure * spread;
                match traction {
                    Some(t) => t.map(|c| c * area),
                    // Outward: away from the piece's points (as given when all lie on it).
                    None => {
                        let outward = if side[piece] < 0.0 { -1.0 } else { 1.0 };
                        n.map(|c| -pressure * outward * c * area)
                    }
                }
            })
            .collect();
        (carriers.iter().map(|&(p, ..)| pts.id[p]).collect::<Vec<u64>>(), forces)
    };
    let name = format!("{call} on group \"{group}\"");
    s.add_point_load(PointLoad::new(name, ids, forces, TimeFunction::Constant(1.0)), factor)
}

pub(super) fn register(engine: &mut Engine, ctx: &Arc<ScriptContext>) {
    engine.register_type_with_name::<MeshHandle>("Mesh");
    engine.register_fn("to_string", |m: &mut MeshHandle| m.describe());
    engine.register_fn("to_debug", |m: &mut MeshHandle| m.describe());
    let c = ctx.clone();
    engine.register_fn("load_mesh", move |file: &str| -> RhaiResult<MeshHandle> {
        let path = c
            .input_path(file)
            .map_err(|why| super::convert::to_rhai(GraniteError::Setup(format!("load_mesh: {why}"))))?;
        let mesh = GmshMesh::read(&path).or_rhai()?;
        Ok(MeshHandle { file: file.to_string(), mesh: Arc::new(mesh) })
    });
    engine.register_fn("groups", |m: &mut MeshHandle| -> Array {
        m.mesh
            .groups
            .iter()
            .enumerate()
            .map(|(g, group)| {
                let mut map = Map::new();
                map.insert("name".into(), Dynamic::from(group.name.clone()));
                map.insert("dim".into(), Dynamic::from(group.dim as i64));
                map.insert("elements".into(), Dynamic::from(m.mesh.elements_of(g).count() as i64));
                Dynamic::from(map)
            })
            .collect()
    });
    engine.register_fn("measure", |m: &mut MeshHandle, group: &str| -> RhaiResult<f64> {
        let g = m.mesh.group(group).or_rhai()?;
        Ok(Simplices::of_group(&m.mesh, g, 3).or_rhai()?.measure())
    });
    engine.register_fn(
        "fill_mesh",
        |s: &mut SimHandle, m: MaterialHandle, mesh: MeshHandle, group: &str, opts: Map| {
            fill_mesh(s, &m, &mesh, group, opts)
        },
    );
    engine.register_fn("fill_mesh", |s: &mut SimHandle, m: MaterialHandle, mesh: MeshHandle, group: &str| {
        fill_mesh(s, &m, &mesh, group, Map::new())
    });
    engine.register_fn("fix", |s: &mut SimHandle, mesh: MeshHandle, group: &str, axis: &str, v: Dynamic| {
        let (nodes, _) = boundary_nodes(s, &mesh, group, "fix")?;
        s.fix_nodes(nodes, axis, v)
    });
    engine.register_fn("fix", |s: &mut SimHandle, mesh: MeshHandle, group: &str, axis: &str| {
        let (nodes, _) = boundary_nodes(s, &mesh, group, "fix")?;
        s.fix_nodes(nodes, axis, Dynamic::from(0.0))
    });
    engine.register_fn("friction", |s: &mut SimHandle, mesh: MeshHandle, group: &str, mu: Dynamic| {
        friction(s, &mesh, group, mu)
    });
    engine.register_fn("point_traction", |s: &mut SimHandle, mesh: MeshHandle, group: &str, t: Dynamic| {
        point_load(s, &mesh, group, Push::Traction(t), Dynamic::from(1.0))
    });
    engine.register_fn(
        "point_traction",
        |s: &mut SimHandle, mesh: MeshHandle, group: &str, t: Dynamic, factor: Dynamic| {
            point_load(s, &mesh, group, Push::Traction(t), factor)
        },
    );
    engine.register_fn("point_pressure", |s: &mut SimHandle, mesh: MeshHandle, group: &str, p: Dynamic| {
        point_load(s, &mesh, group, Push::Pressure(p), Dynamic::from(1.0))
    });
    engine.register_fn(
        "point_pressure",
        |s: &mut SimHandle, mesh: MeshHandle, group: &str, p: Dynamic, factor: Dynamic| {
            point_load(s, &mesh, group, Push::Pressure(p), factor)
        },
    );
    engine.register_fn("traction", |s: &mut SimHandle, mesh: MeshHandle, group: &str, t: Dynamic| {
        traction(s, &mesh, group, t, Dynamic::from(1.0))
    });
    engine.register_fn("traction", |s: &mut SimHandle, mesh: MeshHandle, group: &str, t: Dynamic, f: Dynamic| {
        traction(s, &mesh, group, t, f)
    });
}
