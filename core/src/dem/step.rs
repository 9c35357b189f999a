//! One DEM step: its stages called in a fixed order (`DemSim::step`). The stages live in their
//! own modules: the candidate lists' rebuild (`rebuild`), the contact stage (`contact_stage`), the
//! cuts into parallel pieces (`pieces`) and the gather with the integration (`motion`).

use crate::dem::cell::{shift_after_flip, AxisGoal};
use crate::dem::contact_stage::{
    contact_job_wide, piece_range, ContactJob, Handover, Handovers, Loads, Motions, ScratchGuard, SharedPairs,
    SphereContacts, SphereSurroundings,
};
use crate::dem::contacts::PairList;
use crate::dem::energy::booking::EnergyBooking;
use crate::dem::kind_stage::{BodyContacts, BodyMotion, SphereReactions, Surroundings};
use crate::dem::motion::{
    farther, gather_piece, integrate, integrate_clumps, GatherJob, Motion, PieceState, RigidMotion, SphereConstants,
};
use crate::dem::particles::{ExternalLoads, Spheres};
use crate::dem::pieces::PieceBounds;
use crate::dem::rows::SharedRows;
use crate::dem::sim::{DemSim, DemWorld, ListsBuilt};
use crate::dem::walls::WallMotion;
use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use nalgebra::Matrix3;
use std::sync::OnceLock;
use std::time::Instant;

impl DemSim {
    /// Advances the simulation by one time step.
    pub fn step(&mut self) -> Result<()> {
        let rebuilt = self.world.needs_rebuild;
        if rebuilt {
            self.rebuild_candidates()?;
        }
        let parallel = self.in_parallel();
        // The stages below see the world and the pipeline's own state apart.
        let DemSim { world, skin, stop_on_unstable_dt, rebuilds, energy, built, piece_bounds, handovers, .. } = self;
        let (skin, stop_on_unstable_dt, rebuilds) = (*skin, *stop_on_unstable_dt, *rebuilds);
        CellServo::run(world, parallel);
        // The contact network changes little between rebuilds: checking it then is enough.
        let check = world.time_step_check.due(rebuilt, world.step);
        // The cell deforms over the step; particles follow its affine field on top of their own
        // motion. The contacts of this step see the cell as it was at its start.
        let (deformed, affine, strain_since_build) = match (&world.cell, &built.h) {
            (Some(cell), Some(h0)) => {
                let mut next = cell.clone();
                next.deform(world.dt);
                let f = next.h * h0.try_inverse().unwrap_or_else(Matrix3::identity);
                let growth = (f - Matrix3::identity()).norm();
                (Some(next), Some((cell.velocity_gradient, f)), growth)
            }
            _ => (None, None, 0.0),
        };
        let update = world.cell.as_ref().map(|c| c.update).unwrap_or_default();
        let rigid = RigidMotion { gravity: world.gravity, damping: world.damping, dt: world.dt, affine, update };
        let motion = Motion::new(&rigid);
        let tracking = energy.is_some();
        let mut energy_before = None;
        // Bodies of a plugin kind meet spheres where they all are at the step's start: their
        // reactions join the spheres' loads before the spheres move.
        let histories = tracking.then(|| world.contacts.histories());
        if !world.kinds.is_empty() {
            let c = &mut world.contacts;
            let mut lists = c.take_body_lists();
            let around = Surroundings {
                spheres: &world.spheres,
                walls: &world.walls,
                laws: &c.laws,
                cell: world.cell.as_ref(),
                law_history: c.pair_strides().1,
                dt: world.dt,
                step: world.step,
                time: world.time,
            };
            let settled = BodyContacts::run(&mut world.kinds, &mut lists, &mut c.body_touches, &around);
            c.put_body_lists(lists);
            if let Err(e) = settled {
                world.needs_rebuild = true;
                return Err(e);
            }
        }
        let sphere_loads = !world.kinds.sphere_loads.is_empty();
        let around = SphereSurroundings {
            walls: &world.walls,
            laws: &world.contacts.laws,
            dt: world.dt,
            cell: world.cell.as_ref(),
        };
        let mut moved = if parallel && !check && world.external.is_empty() && !tracking && !sphere_loads {
            ContactsAndMotion::run(
                &mut world.spheres,
                (&mut world.contacts.spheres, &mut world.contacts.sphere_walls),
                (piece_bounds, handovers),
                &around,
                (&built.x, rebuilds),
                &motion,
            )
        } else {
            // The stability check reads this step's contacts before anything moves, so that a
            // step it stops leaves the spheres where they were. It comes once in 1000 steps at
            // most, so such a step runs on this thread alone (the same sums as in parallel).
            // External loads on single spheres and the energy tracker (a console's experiments,
            // not production runs) work between the contact stage and the motion, so they take
            // this path too.
            SphereContacts::run(
                &mut world.spheres,
                (&mut world.contacts.spheres, &mut world.contacts.sphere_walls),
                &around,
            );
            ExternalLoads::run(&mut world.external, &mut world.spheres);
            SphereReactions::run(&world.kinds, &mut world.spheres);
            if check {
                world.check_time_step(stop_on_unstable_dt)?;
            }
            energy_before = histories.map(|history| EnergyBooking::before_motion(&*world, history));
            integrate(&mut world.spheres, &built.x, &motion)
        };
        if deformed.is_some() {
            world.cell = deformed;
        }
        if !world.clumps.is_empty() {
            let clump_moved = integrate_clumps(&mut world.clumps, &mut world.spheres, &built.x, &rigid);
            moved = farther(moved, clump_moved);
        }
        let kind_moved = if world.kinds.is_empty() {
            0.0
        } else {
            BodyMotion::run(&mut world.kinds, &rigid, (world.step, world.time))?
        };
        let wall_moved = WallMotion::run(&mut world.walls, (&built.walls, &mut built.wall_turns), world.dt);
        // The tracker closes the step once everything has moved (clumps and walls too).
        if let (Some(before), Some(tracker)) = (energy_before, energy.as_mut()) {
            EnergyBooking::after_motion(&*world, before, tracker);
        }
        world.time += world.dt;
        world.step += 1;
        // Between two rebuilds every sphere stays within half the skin of where the lists were
        // built (further, and they are rebuilt before the next step). A sphere now further than
        // that plus the smallest radius has moved more than a smallest radius in this one step:
        // contacts can then be missed (it may pass through a wall or another sphere), which no
        // stable run does.
        if moved > 0.5 * skin + built.radius_min {
            return Err(too_fast(world, built, skin));
        }
        if !moved.is_finite() {
            let Some(bad) = (0..world.spheres.len())
                .find(|&i| !world.spheres.x[i].iter().chain(&world.spheres.v[i]).all(|c| c.is_finite()))
            else {
                // Every value is finite but a distance overflowed: a sphere is absurdly fast.
                return Err(too_fast(world, built, skin));
            };
            return Err(GraniteError::Unstable {
                step: world.step,
                time: world.time,
                reason: format!(
                    "non-finite position or velocity of sphere {} (x = {:?}, v = {:?}); the time step may be too large",
                    world.spheres.id.get(bad).copied().unwrap_or(0),
                    world.spheres.x.get(bad),
                    world.spheres.v.get(bad)
                ),
            });
        }
        if let Some(cell) = &mut world.cell {
            if let Some(m) = cell.flip_if_needed() {
                // A sphere's pair with its own image (a thin cell) may come out under the
                // negative shift; the rebuild that follows finds it under the positive one, as a
                // new contact.
                let c = &mut world.contacts;
                for list in [&mut c.spheres, &mut c.bodies, &mut c.body_spheres] {
                    for s in list.shift.iter_mut() {
                        *s = shift_after_flip(&m, *s);
                    }
                    list.resort();
                }
                world.needs_rebuild = true;
            }
        }
        let affine_growth = strain_since_build * (2.0 * built.radius_max + skin);
        if 2.0 * moved + affine_growth > skin || moved + wall_moved > skin {
            world.needs_rebuild = true;
        }
        if !world.kinds.is_empty() {
            let skin = world.kind_skin(skin);
            // Two bodies' centres drift apart by the cell's strain times their distance.
            let k = &world.kinds;
            let widest = (0..k.len()).map(|i| k.bounding_radius(i)).fold(0.0, f64::max);
            let kind_affine_growth = strain_since_build * (2.0 * widest + skin);
            if 2.0 * kind_moved + kind_affine_growth > skin || kind_moved + wall_moved > skin {
                world.needs_rebuild = true;
            }
        }
        Ok(())
    }

    /// Steps on the calling thread only (an RVE inside a parallel loop over material points),
    /// dropping what only the parallel force gather needs, and storage beyond what is held (an
    /// RVE is copied to every material point).
    pub fn set_sequential(&mut self, on: bool) {
        self.sequential = on;
        if on {
            self.spare_pairs = PairList::default();
            self.piece_bounds = PieceBounds::default();
            self.handovers = Handovers::default();
            self.world.contacts.spheres.shrink_to_fit();
            self.world.contacts.sphere_walls.shrink_to_fit();
        }
    }
}

/// The error of a step after which a sphere is further from where the lists saw it than half
/// the skin and the smallest radius: it names that sphere, how far it went and how fast it goes.
fn too_fast(world: &DemWorld, built: &ListsBuilt, skin: f64) -> GraniteError {
    let s = &world.spheres;
    let (far, moved) = built.farthest_moved(&s.x, world.cell.as_ref().map(|c| &c.h)).unwrap_or((0, 0.0));
    let v = s.v.get(far).map_or(0.0, |v| v.iter().map(|c| c * c).sum::<f64>().sqrt());
    let critical = world.critical_dt().map(|c| format!(" (critical_dt() = {c:.4e} s)")).unwrap_or_default();
    GraniteError::Unstable {
        step: world.step,
        time: world.time,
        reason: format!(
            "sphere {} moved {moved:.4e} m since the contact lists were built (it moves at {v:.4e} m/s, {:.4e} m \
             a step of {:.4e} s): more than half the skin ({:.4e} m) and the smallest radius ({:.4e} m) allow \
             between two builds, so contacts would be missed. The forces are too large for this time step: lower \
             dt{critical}, or look for spheres placed overlapping or given such a velocity",
            s.id.get(far).copied().unwrap_or(0),
            v * world.dt,
            world.dt,
            0.5 * skin,
            built.radius_min
        ),
    }
}

/// The periodic cell's servo, a stage before the contacts: where a goal of the cell control is a
/// stress, it reads the stress and axis stiffness of the contacts as they are (in parallel
/// blocks if `parallel`); the control then writes the cell's velocity gradient for this step.
struct CellServo;

impl CellServo {
    fn run(world: &mut DemWorld, parallel: bool) {
        let (Some(control), Some(cell)) = (&world.cell_control, &world.cell) else { return };
        let servo = control.axes.iter().any(|a| matches!(a, AxisGoal::Stress { .. }));
        let (stress, stiffness) =
            if servo { world.stress_and_axis_stiffness(cell.volume(), parallel) } else { ([0.0; 6], [0.0; 3]) };
        let dt = world.dt;
        if let (Some(control), Some(cell)) = (world.cell_control.as_mut(), world.cell.as_mut()) {
            cell.velocity_gradient = control.velocity_gradient(&stress, stiffness, dt);
        }
    }
}

/// The spheres' contact stage and their motion in one parallel pass (`par::run_pieces_then`): a
/// piece's spheres move as soon as no contact piece that reads them is still running, so a worker
/// done with its contacts moves spheres instead of waiting for the other's. The same sums in the
/// same order as [`SphereContacts`] then `integrate`: see `write_back` and `gather_piece`. Reads
/// the surroundings, the spheres' constants and where they were at the build; writes the spheres'
/// motion and loads, the pairs' contacts and history, and the pieces' cuts and handovers.
/// Returns the largest displacement (see `integrate`).
pub(super) struct ContactsAndMotion;

impl ContactsAndMotion {
    pub(super) fn run(
        spheres: &mut Spheres,
        (pairs, wall_pairs): (&mut PairList, &mut PairList),
        (pieces, handovers): (&mut PieceBounds, &mut Handovers),
        around: &SphereSurroundings<'_>,
        (x_at_build, rebuilds): (&[Vec3], u64),
        motion: &Motion,
    ) -> f64 {
        let strides = (pairs.param_stride, pairs.history_stride);
        pieces.refresh(spheres.len(), rebuilds, pairs, wall_pairs);
        let bounds = &*pieces;
        let starts = &bounds.spheres[..];
        let Spheres { x, v, w, radius, force, torque, mass, inertia, blocked, clump, .. } = spheres;
        let rotation = around.laws.iter().any(|l| l.resists_rotation());
        let (x, v, w) = (SharedRows::new(x), SharedRows::new(v), SharedRows::new(w));
        let (walls, laws, dt, cell) = (around.walls, around.laws, around.dt, around.cell);
        let n = starts.len() - 1;
        // Each piece borrows its own pairs, loads and handover in the worker that claims it. Cut
        // and lent from here, in slots that the workers then emptied, each step's descriptors
        // (some 350 bytes a piece) were written over cache lines the other core had last
        // written: 5-8 us of this serial setup in the 10k-sphere deposition on two threads.
        let (sphere_cuts, wall_cuts) = (&bounds.sphere_pairs[..], &bounds.wall_pairs[..]);
        let (sphere_list, wall_list) = (SharedPairs::new(pairs, strides), SharedPairs::new(wall_pairs, strides));
        let (force, torque) = (SharedRows::new(force), SharedRows::new(torque));
        let handovers = SharedRows::new(handovers.fit(n));
        let (mass, inertia, blocked, clump, x_at_build) =
            (&mass[..], &inertia[..], &blocked[..], &clump[..], x_at_build);
        // Who ran each piece's contacts, and for how long (see `PieceBounds::learn`).
        let contacts_timed: Vec<OnceLock<(usize, f64)>> = (0..n).map(|_| OnceLock::new()).collect();
        let timed = |started: Instant| (rayon::current_thread_index().unwrap_or(0), started.elapsed().as_secs_f64());
        let moved = crate::par::run_pieces_then(
            &bounds.reads_from,
            |q| {
                let started = Instant::now();
                let own = starts[q]..starts[q + 1];
                // SAFETY: run_pieces_then runs first(q) once for each piece q, and second(q), which
                // borrows its loads again, only after it; pieces hold disjoint pairs, spheres and
                // handovers; later pieces read this handover only once first(q) has finished.
                let (sphere_pairs, wall_pairs, force, torque, handover) = unsafe {
                    (
                        sphere_list.chunk(piece_range(sphere_cuts, sphere_list.len(), q)),
                        wall_list.chunk(piece_range(wall_cuts, wall_list.len(), q)),
                        force.piece(own.clone()),
                        torque.piece(own),
                        &mut handovers.piece(q..q + 1)[0],
                    )
                };
                // The spheres of pieces reads_from[q]..=q: those of its pairs (a pair's second sphere
                // lies before its first).
                let read = starts[bounds.reads_from[q]]..starts[q + 1];
                let (first, radius) = (read.start, &radius[read.clone()]);
                // SAFETY: run_pieces_then moves the spheres of a piece only once every contact
                // piece that reads them has finished, and these slices end with this closure. A
                // pair outside `read` (a wrong reads_from) panics at its index, as any slice does.
                let (x, v, w) = unsafe { (x.rows(read.clone()), v.rows(read.clone()), w.rows(read)) };
                let sp = Motions { first, x, v, w, radius, cell, rotation };
                let mut scratch = ScratchGuard::take();
                let scratch = &mut *scratch;
                handover.start(q);
                let loads = Loads {
                    first: starts[q],
                    force: &mut *force,
                    torque: &mut *torque,
                    handover: &mut *handover,
                    starts,
                };
                contact_job_wide(ContactJob { sp: &sp, walls, sphere_pairs, wall_pairs, laws, dt, scratch, loads });
                contacts_timed[q].set(timed(started)).ok();
            },
            |p| {
                let started = Instant::now();
                let range = starts[p]..starts[p + 1];
                // Only pieces that read this piece's spheres can have handed loads over to it.
                let later = (p + 1..n).filter(|&q| bounds.reads_from[q] <= p);
                // SAFETY: pieces do not overlap, and run_pieces_then calls this once, after first(p)
                // and every contact piece that reads these spheres (and so every handover to them)
                // have finished.
                let (x, v, w, force, torque, later) = unsafe {
                    let later: Vec<&Handover> = later.map(|q| &handovers.rows(q..q + 1)[0]).collect();
                    let (force, torque) = (force.piece(range.clone()), torque.piece(range.clone()));
                    (x.piece(range.clone()), v.piece(range.clone()), w.piece(range), force, torque, later)
                };
                let moving = PieceState { x, v, w, force, torque };
                let fixed = SphereConstants { mass, inertia, blocked, clump, x_at_build };
                let largest =
                    gather_piece(GatherJob { first: starts[p], part: p, moving, fixed, later: &later, motion });
                (largest, timed(started))
            },
        );
        let timings: Vec<[(usize, f64); 2]> =
            contacts_timed.iter().zip(&moved).map(|(c, m)| [c.get().copied().unwrap_or_default(), m.1]).collect();
        pieces.learn(&timings);
        moved.into_iter().map(|m| m.0).fold(0.0, farther)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dem::cell::PeriodicCell;
    use crate::dem::pieces::RECUT_AFTER_STEPS;
    use crate::ext::{ContactBatch, ContactLaw};
    use crate::math::Vec3;

    /// A normal spring and a drag on the relative velocity: enough to make spheres spin and to
    /// load both spheres of every pair (the laws proper are plugins).
    struct SpringAndDrag(crate::params::Params);

    impl ContactLaw for SpringAndDrag {
        fn name(&self) -> &str {
            "spring_and_drag"
        }
        fn params(&self) -> &crate::params::Params {
            &self.0
        }
        fn param_count(&self) -> usize {
            1
        }
        fn history_count(&self) -> usize {
            0
        }
        fn init_pair(&self, _: &crate::ext::PairInfo, params: &mut [f64]) {
            params[0] = 1e5;
        }
        fn max_normal_stiffness(&self, _: &crate::ext::PairInfo) -> f64 {
            1e5
        }
        fn compute(&self, batch: ContactBatch<'_>) {
            batch.for_each(&mut SpringAndDrag(Default::default()));
        }
    }

    impl crate::ext::contact::ContactPhysics<1, 0> for SpringAndDrag {
        fn contact(&mut self, c: crate::ext::contact::Contact<'_, 1, 0>) -> (Vec3, Vec3) {
            let push = c.params[0] * c.overlap;
            let drag = 0.05;
            (std::array::from_fn(|a| -push * c.normal[a] + drag * c.rel_velocity[a]), [0.0; 3])
        }
    }

    #[test]
    fn any_cut_into_pieces_gives_the_same_motion() {
        // A squeezed, sheared periodic lattice of 12^3 spheres, stepped on one thread and on two
        // with the workers' shares forced to change every step: other cuts each time.
        let run = |threads: usize, shares: &[f64]| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut sim = DemSim::new();
                let m = sim.world.add_material("grains", 2650.0).unwrap();
                sim.world.set_contact_law(Box::new(SpringAndDrag(Default::default())), None).unwrap();
                let (r, side) = (1e-3, 12);
                let spacing = 1.9 * r;
                let width = side as f64 * spacing;
                sim.world.set_cell(Some(PeriodicCell::new_box([width; 3])));
                let hi = [width - 0.5 * spacing + r; 3];
                let placed =
                    crate::dem::generate::lattice([0.5 * spacing - r; 3], hi, spacing, 0.93 * r, 0.01 * r, 3).unwrap();
                for (x, radius) in placed {
                    sim.world.add_sphere(m, x, radius, [0.0; 3]).unwrap();
                }
                sim.world.set_dt(0.2 * sim.world.critical_dt().unwrap()).unwrap();
                let l = &mut sim.world.cell.as_mut().unwrap().velocity_gradient;
                for a in 0..3 {
                    l[(a, a)] = -0.05 / (200.0 * sim.world.dt);
                }
                l[(0, 2)] = 0.1 / (200.0 * sim.world.dt);
                let mut cuts = std::collections::BTreeSet::new();
                let mut shares_cut_for = std::collections::BTreeSet::new();
                for step in 0..200 {
                    let share = shares[step % shares.len()];
                    let mut taught = crate::par::WorkerSpeeds::default();
                    taught.learn(2, [(0, 1.0, 1.0 - share), (1, 1.0, share)].into_iter());
                    sim.piece_bounds.speeds = taught;
                    sim.piece_bounds.age = RECUT_AFTER_STEPS;
                    sim.step().unwrap();
                    cuts.insert(sim.piece_bounds.spheres.clone());
                    shares_cut_for
                        .insert(sim.piece_bounds.shares.iter().map(|s| (s * 100.0).round() as i64).collect::<Vec<_>>());
                }
                (
                    sim.world.spheres.x,
                    sim.world.spheres.w,
                    sim.world.contacts.spheres.touching_count(),
                    cuts.len(),
                    shares_cut_for,
                )
            })
        };
        let one = run(1, &[0.5]);
        let two = run(2, &[0.35, 0.5, 0.65]);
        assert!(one.2 > 2000, "the lattice must be squeezed into contact ({} contacts)", one.2);
        assert!(one.1.iter().any(|w| w.iter().any(|c| *c != 0.0)), "no sphere spins");
        let forced = [35, 50, 65].map(|percent| vec![percent, 100 - percent]);
        assert!(forced.iter().all(|f| two.4.contains(f)), "cuts for the forced shares {forced:?}: {:?}", two.4);
        assert!(two.3 >= 3, "the shares must have cut the spheres in several ways ({} cuts)", two.3);
        assert!(one.0 == two.0 && one.1 == two.1, "the cuts changed the motion");
    }

    #[test]
    fn a_pair_of_materials_without_a_contact_law_is_named() {
        use crate::dem::walls::{Wall, WallShape};
        // A law for sand on sand only: a sand sphere 1 mm from a glass sphere, then from a glass
        // wall (the skin is 2 mm).
        for near_wall in [false, true] {
            let mut sim = DemSim::new();
            let sand = sim.world.add_material("sand", 2650.0).unwrap();
            let glass = sim.world.add_material("glass", 2500.0).unwrap();
            sim.world.set_contact_law(Box::new(SpringAndDrag(Default::default())), Some((sand, sand))).unwrap();
            sim.world.add_sphere(sand, [0.0, 0.0, 0.006], 0.005, [0.0; 3]).unwrap();
            if near_wall {
                sim.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], glass));
            } else {
                sim.world.add_sphere(glass, [0.0, 0.0, -0.005], 0.005, [0.0; 3]).unwrap();
            }
            sim.skin = 0.002;
            let Err(GraniteError::Setup(message)) = sim.rebuild_candidates() else {
                panic!("near a wall: {near_wall}: a pair without a law must be refused");
            };
            assert!(message.contains("\"sand\"") && message.contains("\"glass\""), "{message}");
        }
    }
}
