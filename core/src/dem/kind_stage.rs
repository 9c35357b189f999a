//! The step's stages of the bodies of plugin kinds, each a struct whose `run` names what it reads
//! and what it writes (rapier's `PhysicsPipeline::step` is the model): the bodies' contacts at the
//! step's start, the reactions they hand the spheres, and their motion. None reaches the rest of
//! the scene through `DemSim`: what they read of it is [`Surroundings`].

use crate::dem::cell::PeriodicCell;
use crate::dem::contact_set::ContactSet;
use crate::dem::contacts::PairList;
use crate::dem::kinds::KindScene;
use crate::dem::motion::RigidMotion;
use crate::dem::particles::Spheres;
use crate::dem::rigid::{laws_in_pair_order, move_rigid_bodies, LawContact, RigidSet};
use crate::dem::walls::{Wall, WallShape};
use crate::error::{GraniteError, Result};
use crate::ext::body::{Ball, BodyPairGeometry, KindBodies, PairFailure, PlacedBodies, Plane, Touch, WarmStarts};
use crate::ext::ContactLaw;
use crate::math::{add3, cross3, mat_vec, sub3, Vec3};
use nalgebra::UnitQuaternion;
use std::sync::Arc;

/// What the bodies' stages read of the rest of the scene at a step's start.
pub(crate) struct Surroundings<'a> {
    pub spheres: &'a Spheres,
    pub walls: &'a [Wall],
    pub laws: &'a [Arc<dyn ContactLaw>],
    /// The periodic cell: a pair's second body or sphere may be an image across it, moving with
    /// the cell's affine field.
    pub cell: Option<&'a PeriodicCell>,
    /// History values a pair's law keeps: the geometry's warm starts come after them.
    pub law_history: usize,
    pub dt: f64,
    /// Where the run is, for diagnostics.
    pub step: u64,
    pub time: f64,
}

/// The bodies' contact stage. Reads the surroundings and the bodies' poses and velocities;
/// writes the bodies' loads, their three lists' contacts, law history and warm starts, the
/// contacts the energy tracker reads, and the loads the bodies leave for the spheres.
pub(crate) struct BodyContacts;

/// A touching contact of a body: what its law takes, and where it acts.
struct Found {
    law: LawContact,
    point: Vec3,
}

/// What settles the touches of a step's pairs: each family's placed bodies and the geometries of
/// the pairs of families.
struct Geometries<'a> {
    bodies: &'a KindScene,
    walls: &'a [Wall],
    images: Option<&'a Images>,
    placed: &'a [Box<dyn PlacedBodies + 'a>],
    meetings: &'a [Arc<dyn BodyPairGeometry>],
}

/// In a periodic cell, the bodies with a copy appended for each image of a body that a body pair
/// meets (`x + h n`), so that every geometry sees plain pairs `(i, j)` of bodies where they are:
/// no geometry needs to know of cells. Built where a pair crosses the cell, once a step.
struct Images {
    x: Vec<Vec3>,
    q: Vec<UnitQuaternion<f64>>,
    values: Vec<f64>,
    shape: Vec<u32>,
    family: Vec<u16>,
    /// Each body pair's second body as the geometries meet it: itself, or its image's copy.
    second: Vec<u32>,
}

impl Images {
    /// The images the body pairs `p` of `bodies` meet across `cell`; None when no pair crosses it.
    fn of(bodies: &KindScene, p: &PairList, cell: Option<&PeriodicCell>) -> Option<Images> {
        let cell = cell?;
        if p.shift.iter().all(|s| *s == [0; 3]) {
            return None;
        }
        let (mut x, mut q, mut values) = (bodies.x.clone(), bodies.q.clone(), bodies.values.clone());
        let (mut shape, mut family) = (bodies.shape.clone(), bodies.family.clone());
        let stride = bodies.stride;
        let second = (0..p.len())
            .map(|k| {
                let (j, n) = (p.b[k] as usize, p.shift[k]);
                if n == [0; 3] {
                    return p.b[k];
                }
                x.push(add3(bodies.x[j], cell.shift_vector(n)));
                q.push(bodies.q[j]);
                values.extend_from_slice(&bodies.values[j * stride..(j + 1) * stride]);
                shape.push(bodies.shape[j]);
                family.push(bodies.family[j]);
                (x.len() - 1) as u32
            })
            .collect();
        Some(Images { x, q, values, shape, family, second })
    }
}

/// The bodies as family `own`'s geometry reads them: with the images the pairs meet, if any.
fn view_of<'a>(bodies: &'a KindScene, images: Option<&'a Images>, own: u16) -> KindBodies<'a> {
    match images {
        None => bodies.view(own),
        Some(m) => KindBodies {
            x: &m.x,
            q: &m.q,
            values: &m.values,
            stride: bodies.stride,
            shape: &m.shape,
            shapes: &bodies.shapes,
            family: &m.family,
            own,
        },
    }
}

/// Each pair's offset of its second body or sphere: the image's `h n`, zero outside a cell.
fn image_offsets(list: &PairList, cell: Option<&PeriodicCell>) -> Vec<Vec3> {
    match cell {
        Some(cell) => list.shift.iter().map(|&n| if n == [0; 3] { [0.0; 3] } else { cell.shift_vector(n) }).collect(),
        None => vec![[0.0; 3]; list.len()],
    }
}

/// The pairs one geometry settles: the family of their first body, and of their second where it
/// is a body ([`NO_FAMILY`] for walls and spheres).
type Group = (u16, u16);

const NO_FAMILY: u16 = u16::MAX;

/// The second of a wall pair's group: a wall of a bounded shape (planes are [`NO_FAMILY`]).
const BOUNDED_WALL: u16 = u16::MAX - 1;

/// A list's warm starts: its history, values a pair, where the geometry's start and how many.
type WarmRows<'h> = (&'h mut [f64], usize, usize, usize);

impl Geometries<'_> {
    /// Fills `out` for a list whose pairs fall in `groups`: one call on the whole list when one
    /// geometry settles them all (one family: the list is handed over as it is); otherwise one
    /// call per group, in the order the groups first appear, each on its pairs in list order with
    /// their warm starts copied out and back. A failure names its pair in the whole list.
    fn detect<T: Copy>(
        &self,
        groups: &[Group],
        pairs: &[T],
        (history, stride, own, warm): WarmRows<'_>,
        out: &mut [Option<Touch>],
        call: impl Fn(&Self, Group, &[T], WarmStarts<'_>, &mut [Option<Touch>]) -> std::result::Result<(), PairFailure>,
    ) -> std::result::Result<(), PairFailure> {
        let Some(&first) = groups.first() else { return Ok(()) };
        if groups.iter().all(|&g| g == first) {
            return call(self, first, pairs, WarmStarts::new(history, stride, own, warm), out);
        }
        let mut order: Vec<Group> = Vec::new();
        for &g in groups {
            if !order.contains(&g) {
                order.push(g);
            }
        }
        for group in order {
            let slots: Vec<usize> = (0..groups.len()).filter(|&k| groups[k] == group).collect();
            let chosen: Vec<T> = slots.iter().map(|&k| pairs[k]).collect();
            let mut starts: Vec<f64> =
                slots.iter().flat_map(|&k| &history[k * stride + own..k * stride + own + warm]).copied().collect();
            let mut found = vec![None; slots.len()];
            call(self, group, &chosen, WarmStarts::new(&mut starts, warm, 0, warm), &mut found)
                .map_err(|f| PairFailure { pair: slots[f.pair], reason: f.reason })?;
            for (n, &k) in slots.iter().enumerate() {
                out[k] = found[n];
                history[k * stride + own..k * stride + own + warm].copy_from_slice(&starts[n * warm..(n + 1) * warm]);
            }
        }
        Ok(())
    }

    /// Bodies with bodies, `(i, j, part)`: their family's geometry, or the geometry of their two
    /// families (one point a pair; its normals turned where it takes them the other way round).
    fn bodies(
        &self,
        (fa, fb): Group,
        pairs: &[(u32, u32, u8)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        if fa == fb {
            return self.placed[fa as usize].pairs(pairs, warm, out);
        }
        let k = self.bodies;
        let (na, nb) = (k.families[fa as usize].name.as_str(), k.families[fb as usize].name.as_str());
        let view = |f: u16| view_of(k, self.images, f);
        for m in self.meetings {
            match m.families() {
                [a, b] if a == na && b == nb => {
                    let pairs: Vec<(u32, u32)> = pairs.iter().map(|&(i, j, _)| (i, j)).collect();
                    return m.pairs(view(fa), view(fb), &pairs, warm, out);
                }
                [a, b] if a == nb && b == na => {
                    let turned: Vec<(u32, u32)> = pairs.iter().map(|&(i, j, _)| (j, i)).collect();
                    m.pairs(view(fb), view(fa), &turned, warm, out)?;
                    for t in out.iter_mut().flatten() {
                        t.normal = t.normal.map(|c| -c);
                    }
                    return Ok(());
                }
                _ => {}
            }
        }
        Err(PairFailure { pair: 0, reason: format!("no geometry registered for {na} and {nb} bodies") })
    }

    /// Bodies with walls `(i, wall)`: planes (a point and the normal towards the bodies' side)
    /// and walls of bounded shapes, apart by the group's second.
    fn walls(
        &self,
        (fa, kind): Group,
        pairs: &[(u32, u32, u8)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        if kind == BOUNDED_WALL {
            let bounded: Vec<(u32, &Wall, u8)> =
                pairs.iter().map(|&(i, w, part)| (i, &self.walls[w as usize], part)).collect();
            return self.placed[fa as usize].bounded_walls(&bounded, warm, out);
        }
        let planes: Vec<(u32, Plane)> = pairs
            .iter()
            .map(|&(i, w, part)| {
                let wall = &self.walls[w as usize];
                let normal = match wall.shape {
                    WallShape::Plane { normal } => normal,
                    _ => [0.0; 3],
                };
                (i, Plane { point: wall.position, normal, part })
            })
            .collect();
        self.placed[fa as usize].planes(&planes, warm, out)
    }

    fn spheres(
        &self,
        (fa, _): Group,
        pairs: &[(u32, Ball)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        self.placed[fa as usize].spheres(pairs, warm, out)
    }
}

/// What the second body of a list's pairs is.
#[derive(Clone, Copy)]
enum Side {
    Bodies,
    Walls,
    Spheres,
}

/// The bodies' lists in their order: body pairs, walls, spheres.
const SIDES: [Side; 3] = [Side::Bodies, Side::Walls, Side::Spheres];

impl BodyContacts {
    /// Settles the bodies' contacts in their three lists (body pairs, walls, spheres: forces,
    /// history, `touches`) and sums their loads.
    pub(crate) fn run(
        bodies: &mut KindScene,
        lists: &mut [PairList; 3],
        touches: &mut [Vec<(LawContact, Vec3)>; 3],
        around: &Surroundings<'_>,
    ) -> Result<()> {
        bodies.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        bodies.torque.iter_mut().for_each(|t| *t = [0.0; 3]);
        bodies.sphere_loads.clear();
        if bodies.families.is_empty() {
            return Ok(());
        }
        let started = std::time::Instant::now();
        let found = Self::touching_lists(bodies, around, lists)?;
        let detected = std::time::Instant::now();
        for (n, ((list, side), (touching, offsets))) in lists.iter_mut().zip(SIDES).zip(found).enumerate() {
            touches[n] = touching.iter().map(|f| (f.law, f.point)).collect();
            let points: Vec<Vec3> = touching.iter().map(|f| f.point).collect();
            let contacts: Vec<LawContact> = touching.into_iter().map(|f| f.law).collect();
            let (force, moment) = laws_in_pair_order(around.laws, list, &contacts, around.dt);
            let loads = (&force[..], &moment[..], &offsets[..]);
            Self::sum_loads(bodies, around.spheres, list, (&contacts, &points), loads, side);
        }
        bodies.seconds[0] += (detected - started).as_secs_f64();
        bodies.seconds[1] += detected.elapsed().as_secs_f64();
        Ok(())
    }

    /// The bodies' touching candidate pairs as a step would find them now, list by list (body
    /// pairs, walls, spheres), with their contact points. Runs the geometries alone, on copies of
    /// the lists: the scene is left as it is.
    pub(crate) fn touches_now(
        bodies: &KindScene,
        contacts: &ContactSet,
        around: &Surroundings<'_>,
    ) -> Result<[Vec<(LawContact, Vec3)>; 3]> {
        let mut out: [Vec<(LawContact, Vec3)>; 3] = Default::default();
        if bodies.families.is_empty() {
            return Ok(out);
        }
        let mut lists = [contacts.bodies.clone(), contacts.body_walls.clone(), contacts.body_spheres.clone()];
        for (n, (found, _)) in Self::touching_lists(bodies, around, &mut lists)?.into_iter().enumerate() {
            out[n] = found.into_iter().map(|f| (f.law, f.point)).collect();
        }
        Ok(out)
    }

    /// The touching pairs of the three lists (body pairs, walls, spheres), the bodies placed once
    /// by each family's geometry (with the images the body pairs meet), and each list's image
    /// offsets of its pairs' second members.
    fn touching_lists(
        bodies: &KindScene,
        around: &Surroundings<'_>,
        lists: &mut [PairList; 3],
    ) -> Result<Vec<(Vec<Found>, Vec<Vec3>)>> {
        let (own, warm) = (around.law_history, bodies.warm_values());
        let images = Images::of(bodies, &lists[0], around.cell);
        let placed = (0..bodies.families.len())
            .map(|f| bodies.families[f].geometry.place(view_of(bodies, images.as_ref(), f as u16)))
            .collect::<Result<Vec<_>>>()?;
        let geometries = Geometries {
            bodies,
            walls: around.walls,
            images: images.as_ref(),
            placed: &placed,
            meetings: &bodies.meetings,
        };
        lists
            .iter_mut()
            .zip(SIDES)
            .map(|(list, side)| {
                let offsets = image_offsets(list, around.cell);
                Ok((Self::touching(&geometries, around, list, side, (own, warm), &offsets)?, offsets))
            })
            .collect()
    }

    /// The touching pairs of a list, from one call of each geometry on its share of it (the
    /// whole list for a scene of one family); pairs found apart start their law's history again at
    /// their next touch. `(own, warm)`: the law's history values a pair, and the geometry's after
    /// them.
    fn touching(
        geometries: &Geometries<'_>,
        around: &Surroundings<'_>,
        list: &mut PairList,
        side: Side,
        (own, warm): (usize, usize),
        offsets: &[Vec3],
    ) -> Result<Vec<Found>> {
        let k = geometries.bodies;
        let mut out = vec![None; list.len()];
        let hs = list.history_stride;
        let fam = &k.family;
        let groups: Vec<Group> = match side {
            Side::Bodies => list.a.iter().zip(&list.b).map(|(&a, &b)| (fam[a as usize], fam[b as usize])).collect(),
            Side::Walls => list
                .a
                .iter()
                .zip(&list.b)
                .map(|(&a, &b)| {
                    let plane = matches!(around.walls[b as usize].shape, WallShape::Plane { .. });
                    (fam[a as usize], if plane { NO_FAMILY } else { BOUNDED_WALL })
                })
                .collect(),
            Side::Spheres => list.a.iter().map(|&a| (fam[a as usize], NO_FAMILY)).collect(),
        };
        let done = match side {
            Side::Bodies => {
                let second = geometries.images.map_or(&list.b[..], |m| &m.second[..]);
                let pairs: Vec<(u32, u32, u8)> =
                    (0..list.len()).map(|k| (list.a[k], second[k], list.part_of(k))).collect();
                geometries.detect(&groups, &pairs, (&mut list.history, hs, own, warm), &mut out, Geometries::bodies)
            }
            Side::Walls => {
                let pairs: Vec<(u32, u32, u8)> =
                    (0..list.len()).map(|k| (list.a[k], list.b[k], list.part_of(k))).collect();
                geometries.detect(&groups, &pairs, (&mut list.history, hs, own, warm), &mut out, Geometries::walls)
            }
            Side::Spheres => {
                let s = &around.spheres;
                let pairs: Vec<(u32, Ball)> = (0..list.len())
                    .map(|k| {
                        let b = list.b[k] as usize;
                        (list.a[k], Ball { centre: add3(s.x[b], offsets[k]), radius: s.radius[b] })
                    })
                    .collect();
                geometries.detect(&groups, &pairs, (&mut list.history, hs, own, warm), &mut out, Geometries::spheres)
            }
        };
        if let Err(PairFailure { pair, reason }) = done {
            return Err(GraniteError::Unstable {
                step: around.step,
                time: around.time,
                reason: format!(
                    "the contact of {}; the bodies may overlap too deeply: lower the time step",
                    Self::pair_name(k, around, list, (pair, side), &reason)
                ),
            });
        }
        let mut found = Vec::new();
        for (slot, touch) in out.into_iter().enumerate() {
            let Some(touch) = touch else {
                if list.touching[slot] {
                    list.touching[slot] = false;
                    list.force[slot] = [0.0; 3];
                    list.history[slot * hs..slot * hs + own].iter_mut().for_each(|h| *h = 0.0);
                }
                continue;
            };
            if !(touch.overlap.is_finite() && touch.normal.iter().chain(&touch.point).all(|c| c.is_finite())) {
                return Err(GraniteError::Unstable {
                    step: around.step,
                    time: around.time,
                    reason: format!(
                        "the {} geometry gave a non-finite contact for body {}; the time step may be too large",
                        k.kind_name(list.a[slot] as usize),
                        k.id[list.a[slot] as usize]
                    ),
                });
            }
            let (i, j) = (list.a[slot] as usize, list.b[slot] as usize);
            let at = |v: Vec3, w: Vec3, x: Vec3| add3(v, cross3(w, sub3(touch.point, x)));
            let first = at(k.v[i], k.w[i], k.x[i]);
            let image = offsets[slot];
            let (second, spin) = match side {
                Side::Bodies => (at(k.v[j], k.w[j], add3(k.x[j], image)), k.w[j]),
                Side::Walls => (around.walls[j].point_velocity(touch.point), around.walls[j].spin),
                Side::Spheres => {
                    let s = &around.spheres;
                    (at(s.v[j], s.w[j], add3(s.x[j], image)), s.w[j])
                }
            };
            // Velocities in a cell are fluctuations about the field `L x`: the second body's
            // centre is `L (x_j + h n - x_i)` faster in the field than the first's.
            let field = match (around.cell, side) {
                (Some(cell), Side::Bodies | Side::Spheres) => {
                    let centre_j = if matches!(side, Side::Bodies) { k.x[j] } else { around.spheres.x[j] };
                    mat_vec(&cell.velocity_gradient, sub3(add3(centre_j, image), k.x[i]))
                }
                _ => [0.0; 3],
            };
            let second = add3(second, field);
            let law = LawContact {
                slot,
                normal: touch.normal,
                overlap: touch.overlap,
                rel_velocity: sub3(second, first),
                rel_spin: sub3(spin, k.w[i]),
            };
            found.push(Found { law, point: touch.point });
        }
        Ok(found)
    }

    /// A pair of a list in words, for a diagnostic: "potential bodies 3 and 7: <reason>".
    fn pair_name(
        bodies: &KindScene,
        around: &Surroundings<'_>,
        list: &PairList,
        (pair, side): (usize, Side),
        reason: &str,
    ) -> String {
        let k = bodies;
        let (i, j) = (list.a[pair] as usize, list.b[pair] as usize);
        let (kind, id) = (k.kind_name(i), k.id[i]);
        match side {
            Side::Bodies if k.kind_name(j) != kind => {
                format!("{kind} body {id} and {} body {}: {reason}", k.kind_name(j), k.id[j])
            }
            Side::Bodies => format!("{kind} bodies {id} and {}: {reason}", k.id[j]),
            Side::Walls => format!("{kind} body {id} and wall \"{}\": {reason}", around.walls[j].name),
            Side::Spheres => format!("{kind} body {id} and sphere {}: {reason}", around.spheres.id[j]),
        }
    }

    /// Adds each touching contact's force and moment to its two bodies in pair order: the
    /// law's force acts on the list's first body, its opposite on the second (a sphere's goes to
    /// `sphere_loads`; a wall takes none).
    fn sum_loads(
        k: &mut KindScene,
        spheres: &Spheres,
        list: &mut PairList,
        (contacts, points): (&[LawContact], &[Vec3]),
        (force, moment, offsets): (&[Vec3], &[Vec3], &[Vec3]),
        side: Side,
    ) {
        for (e, (contact, &point)) in contacts.iter().zip(points).enumerate() {
            let slot = contact.slot;
            let (i, j) = (list.a[slot] as usize, list.b[slot] as usize);
            let (f, m) = (force[e], moment[e]);
            list.touching[slot] = true;
            list.force[slot] = f;
            k.force[i] = add3(k.force[i], f);
            k.torque[i] = add3(k.torque[i], add3(cross3(sub3(point, k.x[i]), f), m));
            let back = [-f[0], -f[1], -f[2]];
            // The second body's arm from its image's centre, where the contact was found.
            let image = offsets[slot];
            match side {
                Side::Bodies => {
                    k.force[j] = add3(k.force[j], back);
                    k.torque[j] = sub3(add3(k.torque[j], cross3(sub3(point, add3(k.x[j], image)), back)), m);
                }
                Side::Walls => {}
                Side::Spheres => {
                    let torque = sub3(cross3(sub3(point, add3(spheres.x[j], image)), back), m);
                    k.sphere_loads.push((j as u32, back, torque));
                }
            }
        }
    }
}

/// The bodies' reactions on the spheres. Reads the loads the contact stage left; writes the
/// spheres' forces and torques, in pair order.
pub(crate) struct SphereReactions;

impl SphereReactions {
    pub(crate) fn run(bodies: &KindScene, spheres: &mut Spheres) {
        for &(i, f, t) in &bodies.sphere_loads {
            let i = i as usize;
            spheres.force[i] = add3(spheres.force[i], f);
            spheres.torque[i] = add3(spheres.torque[i], t);
        }
    }
}

/// The bodies' motion. Reads their loads and mass properties; writes their poses and
/// velocities. Returns the largest distance a body's centre moved since the lists were built.
pub(crate) struct BodyMotion;

impl BodyMotion {
    pub(crate) fn run(k: &mut KindScene, motion: &RigidMotion, (step, time): (u64, f64)) -> Result<f64> {
        let set = RigidSet {
            x: &mut k.x,
            v: &mut k.v,
            w: &mut k.w,
            q: &mut k.q,
            mass: &k.mass,
            inertia: &k.inertia,
            fixed: &k.fixed,
            force: &k.force,
            torque: &k.torque,
        };
        move_rigid_bodies(set, &k.x_at_build, motion).map_err(|i| GraniteError::Unstable {
            step,
            time,
            reason: format!(
                "non-finite position or velocity of {} body {} (x = {:?}, v = {:?}); the time step may be too large",
                k.kind_name(i),
                k.id[i],
                k.x[i],
                k.v[i]
            ),
        })
    }
}
