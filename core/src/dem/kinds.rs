//! Bodies of plugin kinds (`ext::body`: capsules, potential particles, ...) in a DEM simulation:
//! their storage and set-up, and the building of their candidate lists (with one another, walls
//! and spheres, from their bounding spheres, across the faces of a periodic cell too; kept in the
//! contact set), rebuilt with the spheres'. Bodies of several families meet where a plugin
//! registers the geometry of their pair (`BodyPairGeometry`). Their part of a step is
//! `kind_stage.rs`.

use crate::dem::broad_phase::{periodic_sphere_pairs, sphere_pairs, wall_pairs, Candidate};
use crate::dem::contacts::{PairKey, PairList};
use crate::dem::pairing::{Other, PairBodies};
use crate::dem::picture::{rigid_picture, RigidBodies};
use crate::dem::sim::DemWorld;
use crate::dem::walls::WallShape;
use crate::error::{GraniteError, Result};
use crate::ext::body::{BodyGeometry, BodyKindFactory, BodyPairGeometry, BodyShape, KindBodies};
use crate::ext::PairInfo;
use crate::io::vtk::PolyData;
use crate::math::Vec3;
use nalgebra::UnitQuaternion;
use std::sync::Arc;

/// A geometry family a simulation's bodies are of: its name, the kind it joined with (what a
/// saved state finds it again by), geometry, shape values per body and warm-start values per
/// pair.
#[derive(Clone)]
pub struct KindInUse {
    pub name: String,
    pub kind: String,
    pub geometry: Arc<dyn BodyGeometry>,
    pub stride: usize,
    pub warm: usize,
}

impl KindInUse {
    pub fn of(factory: &dyn BodyKindFactory) -> KindInUse {
        let geometry = factory.geometry();
        KindInUse {
            name: factory.family().to_string(),
            kind: factory.name().to_string(),
            warm: geometry.warm_values(),
            geometry,
            stride: factory.values_per_shape(),
        }
    }
}

/// The bodies of plugin kinds, their candidate lists and what a step leaves for the spheres.
#[derive(Clone, Default)]
pub struct KindScene {
    /// The families of the bodies, in the order they joined (none before the first body).
    pub families: Vec<KindInUse>,
    /// The geometries of the pairs of families present, found when the second of each joined.
    pub meetings: Vec<Arc<dyn BodyPairGeometry>>,
    /// Each body's family (an index into `families`).
    pub family: Vec<u16>,
    pub shapes: Vec<Arc<dyn BodyShape>>,
    pub shape: Vec<u32>,
    /// Each body's shape values ([`BodyShape::values`]), `stride` a body: the most any family
    /// gives, each body's own first and zeros after them.
    pub values: Vec<f64>,
    pub stride: usize,
    pub id: Vec<u64>,
    pub material: Vec<u16>,
    /// Centre of mass, velocity, angular velocity (world frame), orientation (body to world).
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub w: Vec<Vec3>,
    pub q: Vec<UnitQuaternion<f64>>,
    pub mass: Vec<f64>,
    /// Principal moments of inertia (body frame).
    pub inertia: Vec<Vec3>,
    /// Moved by their own velocity and spin only (container parts).
    pub fixed: Vec<bool>,
    pub force: Vec<Vec3>,
    pub torque: Vec<Vec3>,
    /// Positions when the candidate lists were last built.
    pub(crate) x_at_build: Vec<Vec3>,
    /// Loads on spheres from this step's contacts (sphere, force, torque), in pair order.
    pub(crate) sphere_loads: Vec<(u32, Vec3, Vec3)>,
    /// Seconds the contacts spent in the geometry and in the laws (with the sums) since the
    /// simulation began: what `granite bench potential` reports.
    pub seconds: [f64; 2],
}

impl KindScene {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    pub fn bounding_radius(&self, i: usize) -> f64 {
        self.shapes[self.shape[i] as usize].bounding_radius()
    }

    /// The radius of the sphere of body `i`'s volume: the size an overlap is measured against.
    pub fn equivalent_radius(&self, i: usize) -> f64 {
        (3.0 * self.shapes[self.shape[i] as usize].volume() / (4.0 * std::f64::consts::PI)).cbrt()
    }

    /// Bytes of the bodies' own state (their lists apart).
    pub fn memory_bytes(&self) -> usize {
        let per_body = std::mem::size_of::<u16>() * 2
            + std::mem::size_of::<u32>()
            + std::mem::size_of::<u64>()
            + 7 * std::mem::size_of::<Vec3>()
            + std::mem::size_of::<UnitQuaternion<f64>>()
            + std::mem::size_of::<f64>()
            + 1;
        self.x.capacity() * per_body + self.values.capacity() * std::mem::size_of::<f64>()
    }

    /// The bodies as family `own`'s geometry reads them.
    pub(crate) fn view(&self, own: u16) -> KindBodies<'_> {
        KindBodies {
            x: &self.x,
            q: &self.q,
            values: &self.values,
            stride: self.stride,
            shape: &self.shape,
            shapes: &self.shapes,
            family: &self.family,
            own,
        }
    }

    /// The family of body `i` by name.
    pub fn family_name(&self, i: usize) -> &str {
        &self.families[self.family[i] as usize].name
    }

    /// The kind of body `i` by name.
    pub fn kind_name(&self, i: usize) -> &str {
        self.shapes[self.shape[i] as usize].kind()
    }

    /// Values a pair of the lists keeps for its geometry: the most any family or pair of
    /// families present keeps.
    pub(crate) fn warm_values(&self) -> usize {
        let meetings = self.meetings.iter().map(|m| m.warm_values());
        self.families.iter().map(|f| f.warm).chain(meetings).max().unwrap_or(0)
    }

    /// Starts afresh when no body is left: the next body's family may be any.
    fn forget_families(&mut self) {
        self.families.clear();
        self.meetings.clear();
        self.shapes.clear();
        self.values.clear();
        self.stride = 0;
    }

    /// The family of `kind`, joining it to the scene if it is new: refused when some family
    /// present has no registered geometry with it among `meetings`.
    pub(crate) fn join_family(
        &mut self,
        kind: &dyn BodyKindFactory,
        meetings: &[Arc<dyn BodyPairGeometry>],
    ) -> Result<u16> {
        let name = kind.family();
        if let Some(f) = self.families.iter().position(|f| f.name == name) {
            return Ok(f as u16);
        }
        let mut found = Vec::new();
        for present in &self.families {
            let meeting = meetings.iter().find(|m| {
                let [a, b] = m.families();
                (a == present.name && b == name) || (a == name && b == present.name)
            });
            match meeting {
                Some(m) => found.push(m.clone()),
                None => {
                    let known: Vec<String> = meetings.iter().map(|m| m.name()).collect();
                    return Err(GraniteError::Setup(format!(
                        "{} bodies cannot join {} bodies: no plugin registers the geometry of their contacts \
                         (pairs of families known: {})",
                        kind.name(),
                        present.name,
                        if known.is_empty() { "none".to_string() } else { known.join(", ") }
                    )));
                }
            }
        }
        let new = KindInUse::of(kind);
        if new.stride > self.stride {
            let (old, n) = (self.stride, self.len());
            let mut values = vec![0.0; n * new.stride];
            for i in 0..n {
                values[i * new.stride..i * new.stride + old].copy_from_slice(&self.values[i * old..(i + 1) * old]);
            }
            (self.values, self.stride) = (values, new.stride);
        }
        self.families.push(new);
        self.meetings.extend(found);
        Ok(self.families.len() as u16 - 1)
    }

    /// The world positions of the monitor points ([`BodyShape::monitor_points`]) of the free
    /// bodies: fixed ones are container parts, not grains of a heap.
    pub fn monitor_positions(&self) -> Vec<Vec3> {
        let mut out = Vec::new();
        for i in (0..self.len()).filter(|&i| !self.fixed[i]) {
            for b in self.shapes[self.shape[i] as usize].monitor_points() {
                let w = self.q[i] * nalgebra::Vector3::new(b[0], b[1], b[2]);
                out.push([self.x[i][0] + w[0], self.x[i][1] + w[1], self.x[i][2] + w[2]]);
            }
        }
        out
    }

    /// Keeps the bodies whose flag is true, in order (their lists are the contact set's).
    pub(crate) fn retain(&mut self, keep: &[bool]) {
        use crate::mpm::points::{retain_by as kept, retain_strided};
        retain_strided(&mut self.values, self.stride, keep);
        kept(&mut self.family, keep);
        kept(&mut self.shape, keep);
        kept(&mut self.id, keep);
        kept(&mut self.material, keep);
        kept(&mut self.x, keep);
        kept(&mut self.v, keep);
        kept(&mut self.w, keep);
        kept(&mut self.q, keep);
        kept(&mut self.mass, keep);
        kept(&mut self.inertia, keep);
        kept(&mut self.fixed, keep);
        kept(&mut self.force, keep);
        kept(&mut self.torque, keep);
        kept(&mut self.x_at_build, keep);
        if self.is_empty() {
            self.forget_families();
        }
    }

    /// Mass for a contact's effective mass: infinite for a fixed body.
    fn contact_mass(&self, i: usize) -> f64 {
        if self.fixed[i] {
            f64::INFINITY
        } else {
            self.mass[i]
        }
    }

    /// Kinetic energy of the free bodies (translation and rotation).
    pub fn kinetic_energy(&self) -> f64 {
        (0..self.len())
            .filter(|&i| !self.fixed[i])
            .map(|i| {
                let (v, w) = (self.v[i], self.w[i]);
                let rot = self.q[i].to_rotation_matrix();
                let body_w = rot.inverse() * nalgebra::Vector3::new(w[0], w[1], w[2]);
                let spin: f64 = (0..3).map(|a| self.inertia[i][a] * body_w[a] * body_w[a]).sum();
                0.5 * self.mass[i] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) + 0.5 * spin
            })
            .sum()
    }
}

/// A body of a kind to add ([`DemWorld::add_body`]).
pub struct NewBody<'a> {
    pub kind: &'a dyn BodyKindFactory,
    /// The geometries of pairs of families the registry knows: where the body's family is new
    /// to a scene holding others, those of its pairs with them.
    pub meetings: &'a [Arc<dyn BodyPairGeometry>],
    pub shape: Arc<dyn BodyShape>,
    pub material: u16,
    pub x: Vec3,
    pub q: UnitQuaternion<f64>,
    pub v: Vec3,
    pub w: Vec3,
    pub fixed: bool,
}

impl DemWorld {
    /// Adds a body of a plugin kind; returns its index among the bodies.
    pub fn add_body(&mut self, body: NewBody<'_>) -> Result<usize> {
        let NewBody { kind, meetings, shape, material, x, q, v, w, fixed } = body;
        let density = self
            .materials
            .get(material as usize)
            .ok_or_else(|| GraniteError::Setup(format!("no material with index {material}")))?
            .density;
        if shape.kind() != kind.name() {
            return Err(GraniteError::Other(format!(
                "a {} shape given as a {} body: build shapes with their kind's factory",
                shape.kind(),
                kind.name()
            )));
        }
        let values = shape.values();
        if values.len() != kind.values_per_shape() {
            return Err(GraniteError::Other(format!(
                "body kind {}: a shape gave {} values, its geometry reads {}",
                kind.name(),
                values.len(),
                kind.values_per_shape()
            )));
        }
        let (volume, inertia) = (shape.volume(), shape.inertia_per_density());
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        if !(volume > 0.0 && finite(&x) && finite(&v) && finite(&w) && inertia.iter().all(|&i| i > 0.0)) {
            return Err(GraniteError::Setup(format!(
                "a {} body needs a volume and moments of inertia > 0 and a finite position and velocity",
                kind.name()
            )));
        }
        let k = &mut self.kinds;
        if k.is_empty() {
            k.forget_families();
        }
        let family = k.join_family(kind, meetings)?;
        let index = match k.shapes.iter().position(|s| Arc::ptr_eq(s, &shape)) {
            Some(i) => i,
            None => {
                k.shapes.push(shape);
                k.shapes.len() - 1
            }
        };
        k.shape.push(index as u32);
        k.family.push(family);
        let padding = k.stride - values.len();
        k.values.extend(values);
        k.values.extend(std::iter::repeat_n(0.0, padding));
        k.id.push(self.next_id);
        k.material.push(material);
        k.x.push(x);
        k.v.push(v);
        k.w.push(w);
        k.q.push(q);
        k.mass.push(density * volume);
        k.inertia.push(inertia.map(|i| density * i));
        k.fixed.push(fixed);
        k.force.push([0.0; 3]);
        k.torque.push([0.0; 3]);
        self.next_id += 1;
        self.needs_rebuild = true;
        Ok(k.len() - 1)
    }

    /// Removes the bodies whose flag is false; the pairs of those that stay keep their history.
    pub fn remove_bodies(&mut self, keep: &[bool]) {
        self.kinds.retain(keep);
        let c = &mut self.contacts;
        c.bodies.retain_spheres(keep, true);
        c.body_walls.retain_spheres(keep, false);
        c.body_spheres.retain_spheres(keep, false);
        c.body_touches = Default::default();
        self.needs_rebuild = true;
    }

    /// The Verlet skin of the bodies: the simulation's `skin`, or a tenth of the smallest
    /// bounding radius when none is set.
    pub(crate) fn kind_skin(&self, skin: f64) -> f64 {
        if skin > 0.0 {
            return skin;
        }
        0.1 * (0..self.kinds.len()).map(|i| self.kinds.bounding_radius(i)).fold(f64::INFINITY, f64::min)
    }

    /// The pair info of body `i` and body `j`, wall `j` or sphere `j`.
    pub(crate) fn kind_info(&self, i: usize, j: usize, other: Other<'_>) -> PairInfo {
        let k = &self.kinds;
        let elastic = |m: u16| self.materials.get(m as usize).and_then(|m| m.elastic);
        let s = &self.spheres;
        let (r2, m2, id2, e2) = match other {
            Other::Same => (k.bounding_radius(j), k.contact_mass(j), k.id[j], elastic(k.material[j])),
            Other::Walls => (f64::INFINITY, f64::INFINITY, u64::MAX - j as u64, elastic(self.walls[j].material)),
            Other::Of(_) => (s.radius[j], s.mass[j], s.id[j], elastic(s.material[j])),
        };
        let (lo, hi) = (k.id[i].min(id2), k.id[i].max(id2));
        let seed = crate::ext::contact::uniform(self.seed ^ lo.wrapping_mul(0x100_0000_01B3), hi).to_bits();
        PairInfo {
            radius: [k.bounding_radius(i), r2],
            mass: [k.contact_mass(i), m2],
            seed,
            elastic: [elastic(k.material[i]), e2],
        }
    }

    /// Rebuilds the bodies' candidate lists (pairs still present keep their history). Called
    /// with the spheres' rebuild, with the simulation's skin.
    pub(crate) fn rebuild_kind_pairs(&mut self, skin: f64) -> Result<()> {
        if self.kinds.is_empty() {
            return Ok(());
        }
        let planes_only: Vec<&str> =
            self.kinds.families.iter().filter(|f| !f.geometry.meets_bounded_walls()).map(|f| f.name.as_str()).collect();
        if let Some(w) = self.walls.iter().find(|w| !matches!(w.shape, WallShape::Plane { .. })) {
            if !planes_only.is_empty() {
                return Err(GraniteError::Setup(format!(
                    "wall \"{}\": {} bodies meet plane walls (wall_plane, box_walls), spheres and one another",
                    w.name,
                    planes_only.join(" and ")
                )));
            }
        }
        let k = &self.kinds;
        let ns = self.spheres.len();
        // One broad phase over the spheres and then the bodies (bounding spheres): a pair whose
        // first index is a body's is a body pair (both bodies) or a (body, sphere) pair.
        let mut x = self.spheres.x.clone();
        x.extend_from_slice(&k.x);
        let mut radii = self.spheres.radius.clone();
        radii.extend((0..k.len()).map(|i| k.bounding_radius(i)));
        let skin = self.kind_skin(skin);
        let found = match &self.cell {
            Some(cell) => periodic_sphere_pairs(&x, &radii, skin, cell),
            None => sphere_pairs(&x, &radii, skin),
        };
        let fixed = &k.fixed;
        let (mut bodies, mut spheres): (Vec<Vec<Candidate>>, Vec<Vec<Candidate>>) = (Vec::new(), Vec::new());
        for block in &found {
            let (mut b, mut s) = (Vec::new(), Vec::new());
            for &(a, c, shift) in block.iter().filter(|p| p.0 as usize >= ns) {
                let i = a - ns as u32;
                if c as usize >= ns {
                    // Fixed bodies are moved, not pushed: their contacts with one another would
                    // change nothing.
                    let j = c - ns as u32;
                    if !(fixed[i as usize] && fixed[j as usize]) {
                        b.push((i, j, shift));
                    }
                } else {
                    s.push((i, c, shift));
                }
            }
            bodies.push(b);
            spheres.push(s);
        }
        let mut walls = wall_pairs(&k.x, &radii[ns..], &self.walls, skin);
        walls.iter_mut().for_each(|block| block.retain(|&(a, _, _)| !fixed[a as usize]));
        // A body whose kind bears on a wall, or on a body of its own family, at several points
        // gets a pair for each (a contact manifold), numbered in the pair's `part`.
        let points = |count: fn(&KindInUse) -> usize| -> Vec<u8> {
            k.families.iter().map(|f| count(f).clamp(1, u8::MAX as usize) as u8).collect()
        };
        let (wall_points, body_points) = (points(|f| f.geometry.wall_points()), points(|f| f.geometry.body_points()));
        let family = &k.family;
        let parted = |blocks: Vec<Vec<Candidate>>, parts: &dyn Fn(&Candidate) -> u8| -> Vec<Vec<(Candidate, u8)>> {
            blocks
                .into_iter()
                .map(|block| block.into_iter().flat_map(|c| (0..parts(&c)).map(move |p| (c, p))).collect())
                .collect()
        };
        let bodies = parted(bodies, &|&(i, j, _)| {
            let (fi, fj) = (family[i as usize], family[j as usize]);
            if fi == fj {
                body_points[fi as usize]
            } else {
                1
            }
        });
        let walls = parted(walls, &|&(i, _, _)| wall_points[family[i as usize] as usize]);
        let strides = self.kind_strides();
        let mut lists = self.contacts.take_body_lists();
        let [body_list, wall_list, sphere_list] = &mut lists;
        let missing = self
            .merge_kind_list(body_list, &bodies, strides, Other::Same)
            .or(self.merge_kind_list(wall_list, &walls, strides, Other::Walls))
            .or(self.merge_kind_list(sphere_list, &spheres, strides, Other::Of(&self.spheres.material)));
        self.contacts.put_body_lists(lists);
        // The last step's touches name pairs by their place in the lists as they were.
        self.contacts.body_touches = Default::default();
        if let Some(pair) = missing {
            return Err(self.missing_law(pair));
        }
        self.kinds.x_at_build = self.kinds.x.clone();
        Ok(())
    }

    /// [`DemWorld::merge_with_laws`] of one of the bodies' lists, its candidates in blocks.
    fn merge_kind_list<K: PairKey>(
        &self,
        list: &mut PairList,
        candidates: &[Vec<K>],
        strides: (usize, usize),
        other: Other<'_>,
    ) -> Option<(u16, u16)> {
        let pieces: Vec<&[K]> = candidates.iter().map(|b| &b[..]).collect();
        let owners = PairBodies { material: &self.kinds.material, other, parallel: false };
        self.merge_with_laws(list, &mut PairList::default(), &pieces, strides, owners, |a, b| {
            self.kind_info(a, b, other)
        })
    }

    /// Values per pair of the bodies' lists: the laws' then the geometry's warm starts.
    pub(crate) fn kind_strides(&self) -> (usize, usize) {
        let (p, h) = self.pair_strides();
        (p, h + self.kinds.warm_values())
    }

    /// The bodies' surfaces, with id, material, fixed, velocity and force per triangle.
    pub fn kinds_picture(&self) -> PolyData {
        let k = &self.kinds;
        let surfaces: Vec<(Vec<Vec3>, Vec<[usize; 3]>)> = k.shapes.iter().map(|s| s.surface()).collect();
        let bodies = RigidBodies {
            shape: &k.shape,
            x: &k.x,
            q: &k.q,
            id: &k.id,
            material: &k.material,
            fixed: &k.fixed,
            v: &k.v,
            force: &k.force,
        };
        rigid_picture(&surfaces, bodies)
    }
}
