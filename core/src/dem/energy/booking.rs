//! How a step books its energies in the tracker: the state before the motion, then the
//! exchanges once everything has moved.

use super::EnergyTracker;
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
    /// History of the sphere pairs and of the wall pairs before the contact stage.
    history: (Vec<f64>, Vec<f64>),
    /// Bodies of a plugin kind, as clumps; and the history of their lists (body pairs, walls,
    /// spheres) before their contacts.
    bodies: Vec<(Vec3, Vec3, Vec3, nalgebra::Matrix3<f64>)>,
    body_history: [Vec<f64>; 3],
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
        if let Some(law) = self.world.laws.iter().find(|l| !l.tracks_dissipation()) {
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
    pub(crate) fn before_motion(
        world: &DemWorld,
        history: (Vec<f64>, Vec<f64>),
        body_history: Option<[Vec<f64>; 3]>,
    ) -> BeforeMotion {
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
            body_history: body_history.unwrap_or_default(),
        }
    }

    /// Contact energies of the step, at the positions its forces came from: the elastic energy,
    /// what each contact dissipated, and the work of moving walls.
    fn contact_energies(world: &DemWorld, b: &BeforeMotion) -> (f64, f64, f64, f64) {
        let s = &world.spheres;
        let (mut elastic, mut friction, mut viscous, mut walls) = (0.0, 0.0, 0.0, 0.0);
        let mean = |i: usize| {
            ([0, 1, 2].map(|a| 0.5 * (b.v[i][a] + s.v[i][a])), [0, 1, 2].map(|a| 0.5 * (b.w[i][a] + s.w[i][a])))
        };
        let mut add = |law: u16, normal: Vec3, overlap: f64, rel: (Vec3, Vec3, Vec3), k: usize, wall: bool| {
            let list = if wall { &world.wall_pairs } else { &world.pairs };
            let before = if wall { &b.history.1 } else { &b.history.0 };
            let (ps, hs) = (list.param_stride, list.history_stride);
            let law = &world.laws[law as usize];
            let params = &list.params[k * ps..(k + 1) * ps];
            let after = &list.history[k * hs..(k + 1) * hs];
            elastic += law.elastic_energy(overlap, params, after);
            let step = ContactStep {
                normal,
                overlap,
                rel_velocity: rel.0,
                mean_rel_velocity: rel.1,
                rel_spin: rel.2,
                dt: world.dt,
                params,
                history_before: &before[k * hs..(k + 1) * hs],
                history_after: after,
                force: list.force[k],
            };
            let (f, v) = law.dissipation(&step);
            friction += f;
            viscous += v;
        };
        // The geometry the contact stage used (see `sphere_contacts` and `wall_contacts`), with
        // the velocities it used and the step's mean ones.
        for k in 0..world.pairs.len() {
            if !world.pairs.touching[k] {
                continue;
            }
            let (i, j) = (world.pairs.a[k] as usize, world.pairs.b[k] as usize);
            let (n, overlap, la, lb) = world.pair_geometry(&b.x, k);
            let relative = |vi: Vec3, wi: Vec3, vj: Vec3, wj: Vec3| {
                let spins = [0, 1, 2].map(|a| la * wi[a] + lb * wj[a]);
                let c = cross(spins, n);
                [0, 1, 2].map(|a| (vj[a] - vi[a]) - c[a])
            };
            let ((vi, wi), (vj, wj)) = (mean(i), mean(j));
            let spin = [0, 1, 2].map(|a| b.w[j][a] - b.w[i][a]);
            let rel = (relative(b.v[i], b.w[i], b.v[j], b.w[j]), relative(vi, wi, vj, wj), spin);
            add(world.pairs.law[k], n, overlap, rel, k, false);
        }
        for k in 0..world.wall_pairs.len() {
            if !world.wall_pairs.touching[k] {
                continue;
            }
            let (i, w) = (world.wall_pairs.a[k] as usize, world.wall_pairs.b[k] as usize);
            let wall = &world.walls[w];
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
            let (vm, wm) = mean(i);
            let spin = b.w[i].map(|c| -c);
            add(
                world.wall_pairs.law[k],
                geo.normal,
                -geo.gap,
                (relative(b.v[i], b.w[i]), relative(vm, wm), spin),
                k,
                true,
            );
            // A moving wall works on the sphere through the contact.
            walls += dot(world.wall_pairs.force[k], wall.velocity) * world.dt;
        }
        let (e, f, v, w) = Self::body_contact_energies(world, b);
        (elastic + e, friction + f, viscous + v, walls + w)
    }

    /// The contact energies of the bodies of a plugin kind (with one another, walls and
    /// spheres), from the contacts their step found: elastic energy, losses, and the work of
    /// moving walls on them.
    fn body_contact_energies(world: &DemWorld, b: &BeforeMotion) -> (f64, f64, f64, f64) {
        let (k, s) = (&world.kinds, &world.spheres);
        let (mut elastic, mut friction, mut viscous, mut walls) = (0.0, 0.0, 0.0, 0.0);
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
        for (n, (list, touches)) in k.lists().into_iter().enumerate() {
            let (ps, hs) = (list.param_stride, list.history_stride);
            let before = &b.body_history[n];
            for &(c, point) in touches {
                let slot = c.slot;
                let (i, j) = (list.a[slot] as usize, list.b[slot] as usize);
                let second = match n {
                    0 => body(j, point),
                    1 => world.walls[j].velocity,
                    _ => mean_at((b.x[j], b.v[j], b.w[j]), (s.v[j], s.w[j]), point),
                };
                let first = body(i, point);
                let law = &world.laws[list.law[slot] as usize];
                let params = &list.params[slot * ps..(slot + 1) * ps];
                let after = &list.history[slot * hs..(slot + 1) * hs];
                elastic += law.elastic_energy(c.overlap, params, after);
                let Some(history_before) = before.get(slot * hs..(slot + 1) * hs) else { continue };
                let step = ContactStep {
                    normal: c.normal,
                    overlap: c.overlap,
                    rel_velocity: c.rel_velocity,
                    mean_rel_velocity: [0, 1, 2].map(|a| second[a] - first[a]),
                    rel_spin: c.rel_spin,
                    dt: world.dt,
                    params,
                    history_before,
                    history_after: after,
                    force: list.force[slot],
                };
                let (f, v) = law.dissipation(&step);
                friction += f;
                viscous += v;
                if n == 1 {
                    walls += dot(list.force[slot], world.walls[j].velocity) * world.dt;
                }
            }
        }
        (elastic, friction, viscous, walls)
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
