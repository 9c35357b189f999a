//! The step's stages of the bodies of plugin kinds, each a struct whose `run` names what it reads
//! and what it writes (rapier's `PhysicsPipeline::step` is the model): the bodies' contacts at the
//! step's start, the reactions they hand the spheres, and their motion. None reaches the rest of
//! the scene through `DemSim`: what they read of it is [`Surroundings`].

use crate::dem::contacts::PairList;
use crate::dem::kinds::KindScene;
use crate::dem::motion::RigidMotion;
use crate::dem::particles::Spheres;
use crate::dem::rigid::{laws_in_pair_order, move_rigid_bodies, LawContact, RigidSet};
use crate::dem::walls::{Wall, WallShape};
use crate::error::{GraniteError, Result};
use crate::ext::body::{Ball, PairFailure, PlacedBodies, Plane, WarmStarts};
use crate::ext::ContactLaw;
use crate::math::{add3, cross3, sub3, Vec3};
use std::sync::Arc;

/// What the bodies' stages read of the rest of the scene at a step's start.
pub(crate) struct Surroundings<'a> {
    pub spheres: &'a Spheres,
    pub walls: &'a [Wall],
    pub laws: &'a [Arc<dyn ContactLaw>],
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

/// What the second body of a list's pairs is.
#[derive(Clone, Copy)]
enum Side {
    Bodies,
    Walls,
    Spheres,
}

impl BodyContacts {
    pub(crate) fn run(bodies: &mut KindScene, around: &Surroundings<'_>) -> Result<()> {
        bodies.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        bodies.torque.iter_mut().for_each(|t| *t = [0.0; 3]);
        bodies.sphere_loads.clear();
        let Some(kind) = bodies.kind.clone() else { return Ok(()) };
        let own = around.law_history;
        let started = std::time::Instant::now();
        let mut lists = [
            std::mem::take(&mut bodies.pairs),
            std::mem::take(&mut bodies.wall_pairs),
            std::mem::take(&mut bodies.sphere_pairs),
        ];
        let sides = [Side::Bodies, Side::Walls, Side::Spheres];
        let mut found = Vec::with_capacity(3);
        {
            let placed = kind.geometry.place(bodies.view())?;
            for (list, &side) in lists.iter_mut().zip(&sides) {
                found.push(Self::touching(bodies, around, list, placed.as_ref(), side, (own, kind.warm))?);
            }
        }
        let detected = std::time::Instant::now();
        for (n, ((mut list, side), touching)) in lists.into_iter().zip(sides).zip(found).enumerate() {
            bodies.touches[n] = touching.iter().map(|f| (f.law, f.point)).collect();
            let points: Vec<Vec3> = touching.iter().map(|f| f.point).collect();
            let contacts: Vec<LawContact> = touching.into_iter().map(|f| f.law).collect();
            let (force, moment) = laws_in_pair_order(around.laws, &mut list, &contacts, around.dt);
            Self::sum_loads(bodies, around.spheres, &mut list, (&contacts, &points), (&force, &moment), side);
            let slot = match side {
                Side::Bodies => &mut bodies.pairs,
                Side::Walls => &mut bodies.wall_pairs,
                Side::Spheres => &mut bodies.sphere_pairs,
            };
            *slot = list;
        }
        bodies.seconds[0] += (detected - started).as_secs_f64();
        bodies.seconds[1] += detected.elapsed().as_secs_f64();
        Ok(())
    }

    /// The touching pairs of a list, from one call of the placed bodies' geometry; pairs found
    /// apart start their law's history again at their next touch. `(own, warm)`: the law's
    /// history values a pair, and the geometry's after them.
    fn touching(
        bodies: &KindScene,
        around: &Surroundings<'_>,
        list: &mut PairList,
        placed: &dyn PlacedBodies,
        side: Side,
        (own, warm): (usize, usize),
    ) -> Result<Vec<Found>> {
        let k = bodies;
        let mut out = vec![None; list.len()];
        let hs = list.history_stride;
        let starts = WarmStarts::new(&mut list.history, hs, own, warm);
        let done = match side {
            Side::Bodies => {
                let pairs: Vec<(u32, u32)> = list.a.iter().copied().zip(list.b.iter().copied()).collect();
                placed.pairs(&pairs, starts, &mut out)
            }
            Side::Walls => {
                let pairs: Vec<(u32, Plane)> = list
                    .a
                    .iter()
                    .zip(&list.b)
                    .map(|(&a, &b)| {
                        let wall = &around.walls[b as usize];
                        let normal = match wall.shape {
                            WallShape::Plane { normal } => normal,
                            _ => [0.0; 3],
                        };
                        (a, Plane { point: wall.position, normal })
                    })
                    .collect();
                placed.planes(&pairs, starts, &mut out)
            }
            Side::Spheres => {
                let s = &around.spheres;
                let pairs: Vec<(u32, Ball)> = list
                    .a
                    .iter()
                    .zip(&list.b)
                    .map(|(&a, &b)| (a, Ball { centre: s.x[b as usize], radius: s.radius[b as usize] }))
                    .collect();
                placed.spheres(&pairs, starts, &mut out)
            }
        };
        if let Err(PairFailure { pair, reason }) = done {
            return Err(GraniteError::Unstable {
                step: around.step,
                time: around.time,
                reason: format!(
                    "the contact of {}; the bodies may overlap too deeply: lower the time step",
                    Self::pair_name(bodies, around, list, (pair, side), &reason)
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
                        k.kind.as_ref().map(|k| k.name.as_str()).unwrap_or(""),
                        k.id[list.a[slot] as usize]
                    ),
                });
            }
            let (i, j) = (list.a[slot] as usize, list.b[slot] as usize);
            let at = |v: Vec3, w: Vec3, x: Vec3| add3(v, cross3(w, sub3(touch.point, x)));
            let first = at(k.v[i], k.w[i], k.x[i]);
            let (second, spin) = match side {
                Side::Bodies => (at(k.v[j], k.w[j], k.x[j]), k.w[j]),
                Side::Walls => (around.walls[j].point_velocity(touch.point), around.walls[j].spin),
                Side::Spheres => {
                    let s = &around.spheres;
                    (at(s.v[j], s.w[j], s.x[j]), s.w[j])
                }
            };
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
        let kind = k.kind.as_ref().map(|k| k.name.as_str()).unwrap_or("");
        let (i, j) = (list.a[pair] as usize, list.b[pair] as usize);
        let id = k.id[i];
        match side {
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
        (force, moment): (&[Vec3], &[Vec3]),
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
            match side {
                Side::Bodies => {
                    k.force[j] = add3(k.force[j], back);
                    k.torque[j] = sub3(add3(k.torque[j], cross3(sub3(point, k.x[j]), back)), m);
                }
                Side::Walls => {}
                Side::Spheres => {
                    let torque = sub3(cross3(sub3(point, spheres.x[j]), back), m);
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
                k.kind.as_ref().map(|k| k.name.as_str()).unwrap_or(""),
                k.id[i],
                k.x[i],
                k.v[i]
            ),
        })
    }
}
