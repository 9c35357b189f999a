//! Potential particles (Houlsby 2009; Boon, Houlsby & Utili 2013; thesis 2.2.2.2) as a body kind:
//! rounded convex polyhedra given by a potential function, the thesis's second shape model beside
//! clumps. Three kinds of one family (`potential`), so that they meet in one simulation:
//! `potential_tetra` (the rounded tetrahedron of thesis table 2.2), `potential_box` (rounded boxes,
//! the thesis's container parts) and `potential` (planes of the user's own).
//!
//! Their geometry places every particle's potential in the world frame once a step, then solves
//! each pair's contact problem from the pair's last solution (its warm start, kept with the
//! pair), in parallel, each pair writing only its own values. A sphere of the scene is met as a
//! potential of its own (`k = 1`, no planes), so spheres and potential particles share one scene.

pub mod contact;
pub mod shape;
pub mod walls;

use contact::{detect, detect_plane, Placed, Pose, Solution};
use granite_core::dem::walls::Wall;
use granite_core::ext::body::{
    Ball, BodyGeometry, BodyKindFactory, BodyShape, KindBodies, PairFailure, PlacedBodies, Plane, Touch, WarmStarts,
};
use granite_core::math::{add3, sub3, Vec3};
use granite_core::params::{ParamMap, ParamSpec, Params};
use granite_core::{GraniteError, Result};
use rayon::prelude::*;
use shape::{box_planes, PotentialShape, MASS_RESOLUTION};
use std::sync::{Arc, Mutex, MutexGuard};

/// The family the three kinds share.
pub const FAMILY: &str = "potential";

/// A potential particle's shape as a body kind holds it: the shape, the kind it was built by and
/// the parameters it was built from.
#[derive(Debug)]
pub struct PotentialBody {
    kind: &'static str,
    params: ParamMap,
    pub shape: PotentialShape,
}

impl BodyShape for PotentialBody {
    fn kind(&self) -> &str {
        self.kind
    }
    fn params(&self) -> ParamMap {
        self.params.clone()
    }
    fn values(&self) -> Vec<f64> {
        Vec::new()
    }
    fn bounding_radius(&self) -> f64 {
        self.shape.bounding_radius
    }
    fn volume(&self) -> f64 {
        self.shape.volume
    }
    fn inertia_per_density(&self) -> Vec3 {
        self.shape.inertia_per_density
    }
    /// `f = 0`, triangulated along 128 directions from the centre of mass.
    fn surface(&self) -> (Vec<Vec3>, Vec<[usize; 3]>) {
        self.shape.surface(2)
    }
    fn contains(&self, p: Vec3) -> bool {
        self.shape.value(p) <= 0.0
    }
    /// The vertices of the planes' polytope (for the thesis's tetrahedron, the centres of the
    /// clump's spheres, as in thesis 2.2.2.2).
    fn monitor_points(&self) -> Vec<Vec3> {
        self.shape.monitor_points.clone()
    }
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

impl PotentialBody {
    /// The potential shape of a body, when it is a potential particle.
    pub fn shape_of(body: &dyn BodyShape) -> Option<&PotentialShape> {
        body.as_any().downcast_ref::<PotentialBody>().map(|b| &b.shape)
    }
}

/// The parameters of kind `potential` for planes `n . x = d`, `r`, `R` and `k`.
pub fn planes_params(planes: &[(Vec3, f64)], r: f64, big_r: f64, k: f64) -> ParamMap {
    let mut given: ParamMap = [("r", r), ("R", big_r), ("k", k)].iter().map(|(n, v)| (n.to_string(), *v)).collect();
    for (i, (n, d)) in planes.iter().enumerate() {
        for (c, v) in ["a", "b", "c", "d"].iter().zip([n[0], n[1], n[2], *d]) {
            given.insert(format!("{c}{}", i + 1), v);
        }
    }
    given
}

/// A potential particle to add from Rust: `shape` built by one of the family's kinds, material,
/// centre of mass, orientation (body to world), velocity, spin, and whether it is a container
/// part moved only by its own velocity.
pub struct NewPotential {
    pub shape: Arc<dyn BodyShape>,
    pub material: u16,
    pub x: Vec3,
    pub q: nalgebra::UnitQuaternion<f64>,
    pub v: Vec3,
    pub w: Vec3,
    pub fixed: bool,
}

/// Adds a potential particle to `sim`; its index among the bodies.
pub fn add(sim: &mut granite_core::dem::DemSim, p: NewPotential) -> Result<usize> {
    let kind: &dyn BodyKindFactory = match p.shape.kind() {
        "potential_tetra" => &PotentialTetraKind,
        "potential_box" => &PotentialBoxKind,
        "potential" => &PotentialPlanesKind,
        other => return Err(GraniteError::Setup(format!("a {other} shape is not a potential particle"))),
    };
    let NewPotential { shape, material, x, q, v, w, fixed } = p;
    let meetings = super::body_pair_geometries();
    let new = granite_core::dem::kinds::NewBody { kind, meetings: &meetings, shape, material, x, q, v, w, fixed };
    sim.world.add_body(new)
}

fn body(kind: &'static str, params: ParamMap, shape: PotentialShape) -> Arc<dyn BodyShape> {
    Arc::new(PotentialBody { kind, params, shape })
}

/// The given values of resolved parameters (what a saved state rebuilds the shape with).
fn given_of(params: &Params, specs: &[ParamSpec]) -> ParamMap {
    specs.iter().filter(|s| params.is_set(s.name)).map(|s| (s.name.to_string(), params.get(s.name))).collect()
}

pub struct PotentialTetraKind;

const POTENTIAL_TETRA: &[ParamSpec] = &[
    ParamSpec::optional("r_sphere", 0.3101e-2, "radius r_s of the clump's spheres in m; the rounding radius r = r_s"),
    ParamSpec::optional("r_clump", 0.5e-2, "radius of the sphere the clump is inscribed in, in m"),
    ParamSpec::optional("k", 0.65, "sphericity, in (0, 1] (table 2.2's fit: 0.65)"),
    ParamSpec::unset("R", "shadow sphere's radius in m (default sqrt(2) r_s, the thesis's)"),
];

impl BodyKindFactory for PotentialTetraKind {
    fn name(&self) -> &str {
        "potential_tetra"
    }
    fn family(&self) -> &str {
        FAMILY
    }
    fn description(&self) -> &str {
        "potential particle: the rounded tetrahedron of thesis table 2.2, faces through the tetra clump's sphere centres"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        POTENTIAL_TETRA
    }
    fn build(&self, params: Params) -> Result<Arc<dyn BodyShape>> {
        let (r_s, r_clump) = (params.positive("r_sphere")?, params.positive("r_clump")?);
        let big_r = if params.is_set("R") { params.positive("R")? } else { 2f64.sqrt() * r_s };
        let shape = PotentialShape::rounded_tetrahedron(r_s, r_clump, big_r, params.get("k"))?;
        Ok(body("potential_tetra", given_of(&params, POTENTIAL_TETRA), shape))
    }
    fn values_per_shape(&self) -> usize {
        0
    }
    fn geometry(&self) -> Arc<dyn BodyGeometry> {
        Arc::new(PotentialGeometry::default())
    }
}

pub struct PotentialBoxKind;

const POTENTIAL_BOX: &[ParamSpec] = &[
    ParamSpec::required("hx", "half-size along x in m (the flat part; the rounding adds r)"),
    ParamSpec::required("hy", "half-size along y in m"),
    ParamSpec::required("hz", "half-size along z in m"),
    ParamSpec::unset("r", "rounding radius in m (default a tenth of the smallest half-size)"),
    ParamSpec::optional("k", 0.05, "sphericity, in (0, 1]: small keeps the faces flat (they bow by about k r / 8)"),
];

impl BodyKindFactory for PotentialBoxKind {
    fn name(&self) -> &str {
        "potential_box"
    }
    fn family(&self) -> &str {
        FAMILY
    }
    fn description(&self) -> &str {
        "potential particle: a rounded box (container parts, as the thesis builds its devices)"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        POTENTIAL_BOX
    }
    fn build(&self, params: Params) -> Result<Arc<dyn BodyShape>> {
        let half = [params.positive("hx")?, params.positive("hy")?, params.positive("hz")?];
        let smallest = half.iter().copied().fold(f64::INFINITY, f64::min);
        let r = if params.is_set("r") { params.positive("r")? } else { 0.1 * smallest };
        // The shadow sphere twice the box's half-diagonal: between a face's middle and its
        // corners the sphere term changes by 3/4 k, which moves the face by about k r / 8.
        let big_r = 2.0 * (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt();
        let shape = PotentialShape::new(&box_planes(half), r, big_r, params.get("k"), MASS_RESOLUTION)?;
        Ok(body("potential_box", given_of(&params, POTENTIAL_BOX), shape))
    }
    fn values_per_shape(&self) -> usize {
        0
    }
    fn geometry(&self) -> Arc<dyn BodyGeometry> {
        Arc::new(PotentialGeometry::default())
    }
}

/// Potential particles of planes of the user's own: `a_i x + b_i y + c_i z = d_i` given as
/// parameters `a1, b1, c1, d1, a2, ...` (the normals outwards, the origin the shadow sphere's
/// centre), with `r`, `R` and `k`.
pub struct PotentialPlanesKind;

const POTENTIAL_PLANES: &[ParamSpec] = &[
    ParamSpec::required("r", "rounding radius in m, > 0"),
    ParamSpec::required("R", "shadow sphere's radius in m, > 0"),
    ParamSpec::required("k", "sphericity, in (0, 1]"),
    ParamSpec::required(
        "a1, b1, c1, d1, ...",
        "the planes a_i x + b_i y + c_i z = d_i, normals outwards, i = 1, 2, ...",
    ),
];

impl PotentialPlanesKind {
    /// The planes of `given`: `a1, b1, c1, d1`, then `a2, ...` until a number is missing.
    fn planes(given: &ParamMap) -> Result<Vec<(Vec3, f64)>> {
        let mut planes = Vec::new();
        let mut known: Vec<String> = ["r", "R", "k"].map(String::from).to_vec();
        for i in 1.. {
            let names = ["a", "b", "c", "d"].map(|c| format!("{c}{i}"));
            let found: Vec<Option<f64>> = names.iter().map(|n| given.get(n).copied()).collect();
            if found.iter().all(Option::is_none) {
                break;
            }
            let Some(v) = found.iter().copied().collect::<Option<Vec<f64>>>() else {
                return Err(GraniteError::Setup(format!(
                    "plane {i} of a potential particle needs all of {}",
                    names.join(", ")
                )));
            };
            planes.push(([v[0], v[1], v[2]], v[3]));
            known.extend(names);
        }
        if let Some(extra) = given.keys().find(|k| !known.contains(k)) {
            return Err(GraniteError::Setup(format!(
                "`{extra}` is not a parameter of a potential particle of planes: r, R, k and a1, b1, c1, d1, a2, ... \
                 numbered from 1 without a gap"
            )));
        }
        Ok(planes)
    }
}

impl BodyKindFactory for PotentialPlanesKind {
    fn name(&self) -> &str {
        "potential"
    }
    fn family(&self) -> &str {
        FAMILY
    }
    fn description(&self) -> &str {
        "potential particle of planes of its own (thesis eq. 2.1)"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        POTENTIAL_PLANES
    }
    fn build(&self, params: Params) -> Result<Arc<dyn BodyShape>> {
        let given: ParamMap = ["r", "R", "k"].iter().map(|n| (n.to_string(), params.get(n))).collect();
        self.build_from(&given)
    }
    fn build_from(&self, given: &ParamMap) -> Result<Arc<dyn BodyShape>> {
        let need = |key: &str| {
            given.get(key).copied().ok_or_else(|| {
                GraniteError::Setup(format!("a potential particle of planes needs `{key}` (r, R, k and its planes)"))
            })
        };
        let (r, big_r, k) = (need("r")?, need("R")?, need("k")?);
        let planes = Self::planes(given)?;
        let shape = PotentialShape::new(&planes, r, big_r, k, MASS_RESOLUTION)?;
        Ok(body("potential", given.clone(), shape))
    }
    fn values_per_shape(&self) -> usize {
        0
    }
    fn geometry(&self) -> Arc<dyn BodyGeometry> {
        Arc::new(PotentialGeometry::default())
    }
}

/// Values a pair keeps: the last solution of its contact problem (a point and, between two
/// particles, the weight `lambda`), whether there is one, and the two parts of the last overlap.
const WARM: usize = 7;

/// The geometry of potential particles (the family's one). It keeps the placed potentials'
/// storage from one step to the next (placing 512 particles anew each step, with an allocation
/// each, made `granite bench potential` 10 % slower); a simulation's copy stepping at the same
/// time as its original places into storage of its own.
#[derive(Default)]
pub struct PotentialGeometry {
    kept: Mutex<Vec<Placed>>,
}

/// Where a step's placed potentials live: the geometry's kept storage, or storage of their own.
enum Storage<'a> {
    Kept(MutexGuard<'a, Vec<Placed>>),
    Own(Vec<Placed>),
}

impl Storage<'_> {
    fn get(&self) -> &[Placed] {
        match self {
            Storage::Kept(v) => v,
            Storage::Own(v) => v,
        }
    }
    fn get_mut(&mut self) -> &mut Vec<Placed> {
        match self {
            Storage::Kept(v) => v,
            Storage::Own(v) => v,
        }
    }
}

impl BodyGeometry for PotentialGeometry {
    fn warm_values(&self) -> usize {
        WARM
    }

    fn meets_bounded_walls(&self) -> bool {
        true
    }

    fn place<'a>(&'a self, bodies: KindBodies<'a>) -> Result<Box<dyn PlacedBodies + 'a>> {
        // Where other families meet these, their shapes are among the scene's: only the shapes
        // of this family's bodies are read.
        let shapes: Vec<Option<&PotentialShape>> =
            bodies.shapes.iter().map(|s| PotentialBody::shape_of(s.as_ref())).collect();
        if let Some(i) = (0..bodies.x.len()).find(|&i| bodies.owns(i) && shapes[bodies.shape[i] as usize].is_none()) {
            let kind = bodies.shape_of(i).kind();
            return Err(GraniteError::Other(format!("a {kind} shape among potential particles")));
        }
        let mut placed = match self.kept.try_lock() {
            Ok(kept) => Storage::Kept(kept),
            Err(_) => Storage::Own(Vec::new()),
        };
        let all = placed.get_mut();
        all.resize_with(bodies.x.len(), Placed::default);
        all.par_iter_mut().enumerate().for_each(|(i, p)| {
            if let Some(shape) = shapes[bodies.shape[i] as usize].filter(|_| bodies.owns(i)) {
                let pose = Pose { position: bodies.x[i], rotation: *bodies.q[i].to_rotation_matrix().matrix() };
                p.place(shape, &pose);
            }
        });
        Ok(Box::new(PlacedPotentials { placed }))
    }
}

/// Every particle's potential where it is at the step's start.
struct PlacedPotentials<'a> {
    placed: Storage<'a>,
}

/// Solves each pair of a list from its warm start, in parallel; the first pair (in list order)
/// that would not solve fails the list.
pub(crate) fn solve_pairs<T: Sync>(
    pairs: &[T],
    mut warm: WarmStarts<'_>,
    out: &mut [Option<Touch>],
    one: impl Fn(&T, &mut [f64]) -> std::result::Result<Option<Touch>, String> + Sync,
) -> std::result::Result<(), PairFailure> {
    let failed: Vec<Option<String>> = warm
        .par_per_pair()
        .zip(pairs.par_iter())
        .zip(out.par_iter_mut())
        .map(|((w, pair), slot)| match one(pair, w) {
            Ok(touch) => {
                *slot = touch;
                None
            }
            Err(reason) => Some(reason),
        })
        .collect();
    match failed.into_iter().enumerate().find_map(|(pair, f)| f.map(|reason| (pair, reason))) {
        Some((pair, reason)) => Err(PairFailure { pair, reason }),
        None => Ok(()),
    }
}

impl PlacedPotentials<'_> {
    /// The contact of particle `a` with `b` (a particle or a sphere), from the warm start in `w`.
    fn meet(a: &Placed, b: &Placed, w: &mut [f64]) -> std::result::Result<Option<Touch>, String> {
        // Bounding spheres apart: no solve (the warm start waits for the next touch).
        let d = sub3(b.position, a.position);
        let reach = a.bounding_radius + b.bounding_radius;
        if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > reach * reach
            || a.clear_of(b.position, b.bounding_radius)
            || b.clear_of(a.position, a.bounding_radius)
        {
            return Ok(None);
        }
        // The kept point is relative to `a`'s centre: a pair moved whole (wrapped across a
        // periodic cell) starts where it left off.
        let start = (w[4] == 1.0).then(|| Solution {
            point: add3(a.position, [w[0], w[1], w[2]]),
            lambda: w[3],
            depths: [w[5], w[6]],
        });
        let found = detect(a, b, start).map_err(|e| e.to_string())?;
        w[..3].copy_from_slice(&sub3(found.solution.point, a.position));
        w[3] = found.solution.lambda;
        w[4] = 1.0;
        w[5..7].copy_from_slice(&found.solution.depths);
        Ok(found.touch)
    }
}

impl PlacedBodies for PlacedPotentials<'_> {
    fn pairs(
        &self,
        pairs: &[(u32, u32, u8)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        let placed = self.placed.get();
        solve_pairs(pairs, warm, out, |&(i, j, _), w| Self::meet(&placed[i as usize], &placed[j as usize], w))
    }

    fn planes(
        &self,
        pairs: &[(u32, Plane)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        let placed = self.placed.get();
        solve_pairs(pairs, warm, out, |&(i, plane), w| {
            let a = &placed[i as usize];
            let normal = plane.normal;
            // Clear of the plane by more than the bounding radius: no solve.
            let height = (0..3).map(|c| normal[c] * (a.position[c] - plane.point[c])).sum::<f64>();
            if height > a.bounding_radius {
                return Ok(None);
            }
            let start = (w[4] == 1.0).then(|| add3(a.position, [w[0], w[1], w[2]]));
            let (deepest, found) = detect_plane(a, plane.point, normal, start).map_err(|e| e.to_string())?;
            w[..3].copy_from_slice(&sub3(deepest, a.position));
            w[4] = 1.0;
            Ok(found)
        })
    }

    fn bounded_walls(
        &self,
        pairs: &[(u32, &Wall, u8)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        let placed = self.placed.get();
        solve_pairs(pairs, warm, out, |&(i, wall, _), _| walls::bounded_wall_touch(&placed[i as usize], wall))
    }

    fn spheres(
        &self,
        pairs: &[(u32, Ball)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        let placed = self.placed.get();
        solve_pairs(pairs, warm, out, |&(i, ball), w| {
            Self::meet(&placed[i as usize], &Placed::sphere(ball.centre, ball.radius), w)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A touching pair moved whole by a lattice vector of a periodic cell (what wrapping does)
    /// goes on from its warm start as if it had not moved: the values it keeps do not depend on
    /// where the pair is (a start kept in world coordinates would be the lattice vector away, a far
    /// start that can take a solve past its step limit), and the touch is the same, moved.
    #[test]
    fn a_pair_moved_whole_goes_on_from_its_warm_start() {
        use nalgebra::{Rotation3, Unit, Vector3};
        let (r_s, r_clump) = (0.3101e-2, 0.5e-2);
        let tetra = shape::PotentialShape::rounded_tetrahedron(r_s, r_clump, 2f64.sqrt() * r_s, 0.65).unwrap();
        let turn = |angle: f64| {
            Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)), angle).into_inner()
        };
        let pose = |x: Vec3, angle: f64| Pose { position: x, rotation: turn(angle) };
        let cell_vector = [0.3, -0.2, 0.1];
        let moved = |x: Vec3| add3(x, cell_vector);
        let (xa, xb) = ([0.0; 3], [8.4e-3, 1e-3, 0.0]);
        let mut warm = [0.0; WARM];
        let mut kept = [0.0; WARM];
        let before = PlacedPotentials::meet(
            &Placed::new(&tetra, &pose(xa, 0.3)),
            &Placed::new(&tetra, &pose(xb, 1.0)),
            &mut warm,
        )
        .unwrap()
        .expect("the two overlap");
        kept.copy_from_slice(&warm);
        let after = PlacedPotentials::meet(
            &Placed::new(&tetra, &pose(moved(xa), 0.3)),
            &Placed::new(&tetra, &pose(moved(xb), 1.0)),
            &mut warm,
        )
        .unwrap()
        .expect("still overlapping");
        for v in 0..WARM {
            assert!(
                (warm[v] - kept[v]).abs() < 1e-12,
                "warm start {v}: {} after the move, {} before",
                warm[v],
                kept[v]
            );
        }
        assert!((after.overlap - before.overlap).abs() < 1e-9 * before.overlap, "{after:?} against {before:?}");
        let point = sub3(after.point, cell_vector);
        for a in 0..3 {
            assert!((point[a] - before.point[a]).abs() < 1e-12, "point {point:?} against {:?}", before.point);
            assert!((after.normal[a] - before.normal[a]).abs() < 1e-9);
        }
    }

    /// A shape of planes is rebuilt from the parameters it gives back (what a saved state holds),
    /// and a gap in the numbering or a stray name is refused.
    #[test]
    fn a_shape_of_planes_rebuilds_from_its_parameters() {
        let given = planes_params(&box_planes([2e-3, 3e-3, 4e-3]), 1e-3, 5e-3, 0.3);
        let first = PotentialPlanesKind.build_from(&given).unwrap();
        let again = PotentialPlanesKind.build_from(&first.params()).unwrap();
        assert_eq!(first.volume(), again.volume());
        assert_eq!(first.inertia_per_density(), again.inertia_per_density());
        let mut gap = given.clone();
        gap.shift_remove("a3");
        assert!(PotentialPlanesKind.build_from(&gap).is_err());
        let mut stray = given.clone();
        stray.insert("a9".into(), 1.0);
        assert!(PotentialPlanesKind.build_from(&stray).is_err());
    }
}
