//! How a step books its energies in the tracker: the state before the motion, then the
//! exchanges once everything has moved.

use super::EnergyTracker;
use crate::dem::contact_set::{MemberKind, Pairing};
use crate::dem::particles::{dof, FREE};
use crate::dem::sim::{DemSim, DemWorld};
use crate::error::{GraniteError, Result};
use crate::ext::contact::ContactStep;
use crate::math::Vec3;

/// The state before a step's motion that the tracker compares with the state after.
pub(crate) struct BeforeMotion {
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    w: Vec<Vec3>,
    /// Clumps: centre, velocity, angular velocity and inertia tensor in the world frame.
    clumps: Vec<(Vec3, Vec3, Vec3, nalgebra::Matrix3<f64>)>,
    /// The history of each list of the contact set before the step's contacts.
    history: [Vec<f64>; 5],
    /// Bodies of a plugin kind, as clumps.
    bodies: Vec<(Vec3, Vec3, Vec3, nalgebra::Matrix3<f64>)>,
}

/// A touching contact as the booking reads it: its pair, its geometry and the relative motion
/// of the second member's contact point with respect to the first's at the contact stage and
/// over the step (the mean of before and after the motion), and the wall's velocity for a wall.
struct Booked {
    slot: usize,
    normal: Vec3,
    overlap: f64,
    rel_velocity: Vec3,
    mean_rel_velocity: Vec3,
    rel_spin: Vec3,
    wall_velocity: Option<Vec3>,
}

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// A rigid body's step (a clump, or a body of a plugin kind): its kinetic energy across the
/// step, its gravitational energy before it, and the damping's work. Translation as a sphere's;
/// rotation by Euler's equations in the world frame, `I w' = T - w x (I w)`: damping is the part
/// of the change beyond that free one. (The gyroscopic term and the turning of `I` make the
/// rotational energy only approximately conserved by the integration: an error of the scheme,
/// not a loss.) `was`: centre, velocity, spin and world inertia before the step.
fn rigid_energies(
    (x0, v0, w0, i_world): (Vec3, Vec3, Vec3, nalgebra::Matrix3<f64>),
    (m, v1, w1): (f64, Vec3, Vec3),
    (force, torque): (Vec3, Vec3),
    g: Vec3,
    dt: f64,
) -> [f64; 3] {
    let (mut kinetic, mut damping) = (0.0, 0.0);
    for a in 0..3 {
        kinetic += 0.5 * m * v0[a] * v1[a];
        let extra = m * ((v1[a] - v0[a]) / dt - (force[a] / m + g[a]));
        damping -= extra * 0.5 * (v0[a] + v1[a]) * dt;
    }
    let (w0v, w1v) = (nalgebra::Vector3::from(w0), nalgebra::Vector3::from(w1));
    kinetic += 0.5 * w0v.dot(&(i_world * w1v));
    let free = nalgebra::Vector3::from(torque) - w0v.cross(&(i_world * w0v));
    let extra = i_world * ((w1v - w0v) / dt) - free;
    damping -= extra.dot(&(0.5 * (w0v + w1v))) * dt;
    [kinetic, -m * dot(g, x0), damping]
}

impl DemSim {
    /// Starts (or stops) tracking energy from the next step. Periodic cells are not covered, nor
    /// laws that do not account for their losses.
    pub fn track_energy(&mut self, on: bool) -> Result<()> {
        if !on {
            self.energy = None;
            return Ok(());
        }
        if self.world.cell.is_some() {
            return Err(GraniteError::Setup("energy tracking covers open domains, not periodic cells".into()));
        }
        if let Some(w) = self.world.walls.iter().find(|w| w.spin != [0.0; 3]) {
            return Err(GraniteError::Setup(format!(
                "energy tracking covers walls that translate; wall \"{}\" spins",
                w.name
            )));
        }
        if let Some(law) = self.world.contacts.laws.iter().find(|l| !l.tracks_dissipation()) {
            return Err(GraniteError::Setup(format!(
                "contact law `{}` does not account for its losses: energy cannot be tracked with it",
                law.name()
            )));
        }
        self.energy = Some(EnergyTracker::default());
        Ok(())
    }
}

/// The energy booking, a stage of a tracked step: before the motion it reads the world (after the
/// contact stage) into a [`BeforeMotion`]; once everything has moved it reads the world again and
/// books the step's exchanges in the tracker.
pub(crate) struct EnergyBooking;

impl EnergyBooking {
    /// What the tracker keeps of a step before its motion (called after the contact stage).
    /// `history`: each list's before the step's contacts (see [`ContactSet::histories`]).
    pub(crate) fn before_motion(world: &DemWorld, history: [Vec<f64>; 5]) -> BeforeMotion {
        let s = &world.spheres;
        let rigid = |x: &[Vec3], v: &[Vec3], w: &[Vec3], q: &[nalgebra::UnitQuaternion<f64>], inertia: &[Vec3]| {
            (0..x.len())
                .map(|c| {
                    let rot = q[c].to_rotation_matrix();
                    let body = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::from(inertia[c]));
                    (x[c], v[c], w[c], rot.matrix() * body * rot.matrix().transpose())
                })
                .collect::<Vec<_>>()
        };
        let (cl, k) = (&world.clumps, &world.kinds);
        BeforeMotion {
            x: s.x.clone(),
            v: s.v.clone(),
            w: s.w.clone(),
            clumps: rigid(&cl.x, &cl.v, &cl.w, &cl.q, &cl.inertia),
            history,
            bodies: rigid(&k.x, &k.v, &k.w, &k.q, &k.inertia),
        }
    }

    /// Contact energies of the step, at the positions its forces came from: the elastic energy,
    /// what each contact dissipated, and the work of moving walls; one pass over every list of
    /// the contact set.
    fn contact_energies(world: &DemWorld, b: &BeforeMotion) -> (f64, f64, f64, f64) {
        let (mut elastic, mut friction, mut viscous, mut walls) = (0.0, 0.0, 0.0, 0.0);
        for ((pairing, list), before) in world.contacts.lists().into_iter().zip(&b.history) {
            let (ps, hs) = (list.param_stride, list.history_stride);
            let booked = match pairing {
                Pairing::SphereSphere => Self::sphere_pairs(world, b),
                Pairing::SphereWall => Self::sphere_walls(world, b),
                _ => Self::body_contacts(world, b, pairing),
            };
            for c in booked {
                let k = c.slot;
                let law = &world.contacts.laws[list.law[k] as usize];
                let params = &list.params[k * ps..(k + 1) * ps];
                let after = &list.history[k * hs..(k + 1) * hs];
                elastic += law.elastic_energy(c.overlap, params, after);
                // A pair new to the lists since the step began has no history before it.
                let Some(history_before) = before.get(k * hs..(k + 1) * hs) else { continue };
                let step = ContactStep {
                    normal: c.normal,
                    overlap: c.overlap,
                    rel_velocity: c.rel_velocity,
                    mean_rel_velocity: c.mean_rel_velocity,
                    rel_spin: c.rel_spin,
                    dt: world.dt,
                    params,
                    history_before,
                    history_after: after,
                    force: list.force[k],
                };
                let (f, v) = law.dissipation(&step);
                friction += f;
                viscous += v;
                // A moving wall works on the grain through the contact.
                if let Some(velocity) = c.wall_velocity {
                    walls += dot(list.force[k], velocity) * world.dt;
                }
            }
        }
        (elastic, friction, viscous, walls)
    }

    /// The step's mean velocity and spin of sphere `i`.
    fn sphere_mean(world: &DemWorld, b: &BeforeMotion, i: usize) -> (Vec3, Vec3) {
        let s = &world.spheres;
        ([0, 1, 2].map(|a| 0.5 * (b.v[i][a] + s.v[i][a])), [0, 1, 2].map(|a| 0.5 * (b.w[i][a] + s.w[i][a])))
    }

    /// The touching sphere pairs with the geometry the contact stage used (see
    /// `sphere_contacts`), at the velocities it used and the step's mean ones.
    fn sphere_pairs(world: &DemWorld, b: &BeforeMotion) -> Vec<Booked> {
        let p = &world.contacts.spheres;
        (0..p.len())
            .filter(|&k| p.touching[k])
            .map(|k| {
                let (i, j) = (p.a[k] as usize, p.b[k] as usize);
                let (n, overlap, la, lb) = world.pair_geometry(&b.x, k);
                let relative = |vi: Vec3, wi: Vec3, vj: Vec3, wj: Vec3| {
                    let spins = [0, 1, 2].map(|a| la * wi[a] + lb * wj[a]);
                    let c = cross(spins, n);
                    [0, 1, 2].map(|a| (vj[a] - vi[a]) - c[a])
                };
                let ((vi, wi), (vj, wj)) = (Self::sphere_mean(world, b, i), Self::sphere_mean(world, b, j));
                Booked {
                    slot: k,
                    normal: n,
                    overlap,
                    rel_velocity: relative(b.v[i], b.w[i], b.v[j], b.w[j]),
                    mean_rel_velocity: relative(vi, wi, vj, wj),
                    rel_spin: [0, 1, 2].map(|a| b.w[j][a] - b.w[i][a]),
                    wall_velocity: None,
                }
            })
            .collect()
    }

    /// The touching sphere-wall pairs with the geometry the contact stage used (see
    /// `wall_contacts`).
    fn sphere_walls(world: &DemWorld, b: &BeforeMotion) -> Vec<Booked> {
        let (p, s) = (&world.contacts.sphere_walls, &world.spheres);
        let mut out = Vec::new();
        for k in (0..p.len()).filter(|&k| p.touching[k]) {
            let (i, wall) = (p.a[k] as usize, &world.walls[p.b[k] as usize]);
            // The wall as it was at the contact stage (it has moved since by v dt): the same
            // geometry as the sphere moved on by v dt against the wall where it is now.
            let shift = wall.velocity.map(|c| c * world.dt);
            let ahead = [0, 1, 2].map(|a| b.x[i][a] + shift[a]);
            let Some(geo) = wall.contact(ahead, s.radius[i], 0.0) else { continue };
            let arm = [0, 1, 2].map(|a| geo.point[a] - ahead[a]);
            let relative = |v: Vec3, w: Vec3| {
                let spin = cross(w, arm);
                [0, 1, 2].map(|a| wall.velocity[a] - (v[a] + spin[a]))
            };
            let (vm, wm) = Self::sphere_mean(world, b, i);
            out.push(Booked {
                slot: k,
                normal: geo.normal,
                overlap: -geo.gap,
                rel_velocity: relative(b.v[i], b.w[i]),
                mean_rel_velocity: relative(vm, wm),
                rel_spin: b.w[i].map(|c| -c),
                wall_velocity: Some(wall.velocity),
            });
        }
        out
    }

    /// The touching contacts of a body list as the bodies' stage found them (their geometry is
    /// the plugin's), with the mean velocities of their points over the step.
    fn body_contacts(world: &DemWorld, b: &BeforeMotion, pairing: Pairing) -> Vec<Booked> {
        let (k, s) = (&world.kinds, &world.spheres);
        let list = world.contacts.list(pairing);
        let Some(n) = pairing.body_list() else { return Vec::new() };
        // A body's or a sphere's velocity at `point` over the step: the mean of before and after.
        let mean_at = |(x, v0, w0): (Vec3, Vec3, Vec3), (v1, w1): (Vec3, Vec3), point: Vec3| {
            let arm = [0, 1, 2].map(|a| point[a] - x[a]);
            let (v, w) = ([0, 1, 2].map(|a| 0.5 * (v0[a] + v1[a])), [0, 1, 2].map(|a| 0.5 * (w0[a] + w1[a])));
            let spin = cross(w, arm);
            [0, 1, 2].map(|a| v[a] + spin[a])
        };
        let body = |i: usize, point: Vec3| {
            let (x, v, w, _) = b.bodies[i];
            mean_at((x, v, w), (k.v[i], k.w[i]), point)
        };
        let touches = &world.contacts.body_touches[n];
        touches
            .iter()
            .map(|&(c, point)| {
                let (i, j) = (list.a[c.slot] as usize, list.b[c.slot] as usize);
                let second = match pairing.second() {
                    MemberKind::Body => body(j, point),
                    MemberKind::Wall => world.walls[j].velocity,
                    MemberKind::Sphere => mean_at((b.x[j], b.v[j], b.w[j]), (s.v[j], s.w[j]), point),
                };
                let first = body(i, point);
                Booked {
                    slot: c.slot,
                    normal: c.normal,
                    overlap: c.overlap,
                    rel_velocity: c.rel_velocity,
                    mean_rel_velocity: [0, 1, 2].map(|a| second[a] - first[a]),
                    rel_spin: c.rel_spin,
                    wall_velocity: (pairing.second() == MemberKind::Wall).then(|| world.walls[j].velocity),
                }
            })
            .collect()
    }

    /// Closes a tracked step after the motion.
    pub(crate) fn after_motion(world: &DemWorld, before: BeforeMotion, tracker: &mut EnergyTracker) {
        let (elastic, friction, viscous, walls) = Self::contact_energies(world, &before);
        let dt = world.dt;
        let g = world.gravity;
        let s = &world.spheres;
        let (mut kinetic, mut gravitational, mut damping, mut boundary) = (0.0, 0.0, 0.0, walls);
        for i in 0..s.len() {
            if s.clump[i] != FREE {
                continue;
            }
            let m = s.mass[i];
            let inertia = s.inertia[i];
            gravitational -= m * dot(g, before.x[i]);
            for a in 0..3 {
                // Translation and rotation of one axis: the force that changed the velocity
                // beyond the applied ones is damping on a free axis, a constraint on a blocked one.
                let mut account = |mass: f64, old: f64, new: f64, applied_acc: f64, blocked: bool| {
                    kinetic += 0.5 * mass * old * new;
                    let extra = mass * ((new - old) / dt - applied_acc);
                    let work = extra * 0.5 * (old + new) * dt;
                    if blocked {
                        boundary += work;
                    } else {
                        damping -= work;
                    }
                };
                let blocked = s.blocked[i];
                account(m, before.v[i][a], s.v[i][a], s.force[i][a] / m + g[a], blocked & (dof::X << a) != 0);
                account(inertia, before.w[i][a], s.w[i][a], s.torque[i][a] / inertia, blocked & (dof::RX << a) != 0);
            }
        }
        // Clumps: their members' motion is the clump's.
        let cl = &world.clumps;
        for (c, &was) in before.clumps.iter().enumerate() {
            let e = rigid_energies(was, (cl.mass[c], cl.v[c], cl.w[c]), (cl.force[c], cl.torque[c]), g, dt);
            (kinetic, gravitational, damping) = (kinetic + e[0], gravitational + e[1], damping + e[2]);
        }
        // Bodies of a plugin kind: the free ones as clumps; a fixed one, moved at its own
        // velocity and spin, works on what it touches against the loads they put on it.
        let k = &world.kinds;
        for (i, &was) in before.bodies.iter().enumerate() {
            if k.fixed[i] {
                boundary -= (dot(k.force[i], was.1) + dot(k.torque[i], was.2)) * dt;
                continue;
            }
            let e = rigid_energies(was, (k.mass[i], k.v[i], k.w[i]), (k.force[i], k.torque[i]), g, dt);
            (kinetic, gravitational, damping) = (kinetic + e[0], gravitational + e[1], damping + e[2]);
        }
        // External loads are in the spheres' forces: their work, over the step's mean velocities.
        for load in &world.external {
            if let Some(i) = world.load_index(load) {
                let mean = |old: Vec3, new: Vec3| [0, 1, 2].map(|a| 0.5 * (old[a] + new[a]));
                boundary += dot(load.force, mean(before.v[i], s.v[i])) * dt;
                boundary += dot(load.torque, mean(before.w[i], s.w[i])) * dt;
            }
        }
        {
            let e = tracker;
            e.kinetic = kinetic;
            e.gravitational = gravitational;
            e.elastic = elastic;
            // The losses of this step come after the state at x_n that the totals compare.
            let total = e.total();
            if e.initial_total.is_none() {
                e.initial_total = Some(total);
            }
            e.friction += friction;
            e.viscous += viscous;
            e.damping += damping;
            e.boundary_work += boundary;
        }
    }
}
