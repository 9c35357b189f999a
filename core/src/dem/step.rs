//! One DEM step as stages called in a fixed order; each is a free function that shows what it
//! reads and writes.

use crate::dem::broad_phase::{periodic_sphere_pairs, sphere_pairs, wall_pairs, Candidate};
use crate::dem::cell::{shift_after_flip, AxisGoal, PeriodicCell};
use crate::dem::clump::Clumps;
use crate::dem::contacts::PairList;
use crate::dem::particles::{dof, Spheres, FREE};
use crate::dem::rows::SharedRows;
use crate::dem::sim::DemSim;
use crate::dem::walls::Wall;
use crate::error::{GraniteError, Result};
use crate::ext::{ContactBatch, ContactLaw};
use crate::math::{dot3, mat_vec, Vec3};
use crate::simd::{self, add4, mat_vec4, mul4, narrow, scale4, sub4, widen, Lanes};
use nalgebra::Matrix3;
use std::ops::Range;
use std::sync::{Arc, OnceLock};
use std::time::Instant;

/// Pairs per law call.
const CHUNK: usize = 128;

/// Most pairs a parallel piece of a rebuild's merge holds (each finds its place in the old list by
/// bisection, so pieces can be small enough for two workers to share the merge evenly).
const MERGE_PIECE: usize = 1024;
/// Fewest spheres worth a parallel piece of their own (with their pairs). Every piece boundary
/// hands loads over (see `write_back`), which costs instructions: the 1500-sphere periodic RVE,
/// stepped in the pieces of two workers on one thread, took 11 % more instructions than the
/// sequential pass in 11 pieces of 128 spheres or more, and 6.6 % in 4 of 375 (callgrind).
const MIN_SPHERES_PER_PIECE: usize = 375;
/// Fewest spheres in a simulation renumbered in space before it first runs.
const MIN_SPHERES_TO_ORDER: usize = 1024;
/// Fewest spheres stepped in parallel (enough for several pieces): below, pieces are not
/// regions of space (see `order_spheres_in_space`), and two threads were slower than one
/// (periodic RVEs, best of 7: 1000 spheres 110 against 98 us a step; 1500: 121 against 148).
const MIN_SPHERES_IN_PARALLEL: usize = MIN_SPHERES_TO_ORDER;
/// Most per-pair parameters / history values a contact law may use.
pub const MAX_PARAMS: usize = 16;
pub const MAX_HISTORY: usize = 16;

#[inline(always)]
fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline(always)]
fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

impl DemSim {
    /// Advances the simulation by one time step.
    pub fn step(&mut self) -> Result<()> {
        let rebuilt = self.needs_rebuild;
        if rebuilt {
            self.rebuild_candidates()?;
        }
        let servo =
            self.cell_control.as_ref().is_some_and(|c| c.axes.iter().any(|a| matches!(a, AxisGoal::Stress { .. })));
        if let (Some(control), Some(cell)) = (&self.cell_control, &self.cell) {
            let (stress, stiffness) =
                if servo { self.stress_and_axis_stiffness(cell.volume()) } else { ([0.0; 6], [0.0; 3]) };
            let l = control.velocity_gradient(&stress, stiffness, self.dt);
            if let Some(cell) = self.cell.as_mut() {
                cell.velocity_gradient = l;
            }
        }
        let parallel = self.in_parallel();
        // The contact network changes little between rebuilds: checking it then is enough.
        let check = match self.last_check {
            None => true,
            Some(at) => rebuilt && self.step >= at + crate::dem::stability::CHECK_EVERY,
        };
        // The cell deforms over the step; particles follow its affine field on top of their own
        // motion. The contacts of this step see the cell as it was at its start.
        let (deformed, affine, strain_since_build) = match (&self.cell, &self.h_at_build) {
            (Some(cell), Some(h0)) => {
                let mut next = cell.clone();
                next.deform(self.dt);
                let f = next.h * h0.try_inverse().unwrap_or_else(Matrix3::identity);
                let growth = (f - Matrix3::identity()).norm();
                (Some(next), Some((cell.velocity_gradient, f)), growth)
            }
            _ => (None, None, 0.0),
        };
        let motion = Motion::new(self.gravity, self.damping, self.dt, affine);
        let tracking = self.energy.is_some();
        let mut energy_before = None;
        let mut moved = if parallel && !check && self.external.is_empty() && !tracking {
            self.contacts_and_motion(&motion)
        } else {
            // The stability check reads this step's contacts before anything moves, so that a
            // step it stops leaves the spheres where they were. It comes once in 1000 steps at
            // most, so such a step runs on this thread alone (the same sums as in parallel).
            // External loads on single spheres and the energy tracker (a console's experiments,
            // not production runs) work between the contact stage and the motion, so they take
            // this path too.
            let history = tracking.then(|| (self.pairs.history.clone(), self.wall_pairs.history.clone()));
            self.contacts();
            self.apply_external_loads();
            if check {
                self.check_time_step()?;
            }
            energy_before = history.map(|history| self.energy_before_motion(history));
            integrate(&mut self.spheres, &self.x_at_build, &motion)
        };
        if deformed.is_some() {
            self.cell = deformed;
        }
        if !self.clumps.is_empty() {
            let clump_moved = integrate_clumps(
                &mut self.clumps,
                &mut self.spheres,
                &self.x_at_build,
                self.gravity,
                self.damping,
                self.dt,
                affine,
            );
            moved = farther(moved, clump_moved);
        }
        let mut wall_moved: f64 = 0.0;
        for (w, at) in self.walls.iter_mut().zip(&self.walls_at_build) {
            for a in 0..3 {
                w.position[a] += w.velocity[a] * self.dt;
            }
            let d = sub(w.position, *at);
            wall_moved = wall_moved.max((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
        }
        // The tracker closes the step once everything has moved (clumps and walls too).
        if let Some(before) = energy_before {
            self.energy_after_motion(before);
        }
        self.time += self.dt;
        self.step += 1;
        // Between two rebuilds every sphere stays within half the skin of where the lists were
        // built (further, and they are rebuilt before the next step). A sphere now further than
        // that plus the smallest radius has moved more than a smallest radius in this one step:
        // contacts can then be missed (it may pass through a wall or another sphere), which no
        // stable run does.
        if moved > 0.5 * self.skin + self.radius_min_at_build {
            return Err(self.too_fast());
        }
        if !moved.is_finite() {
            let Some(bad) = (0..self.spheres.len())
                .find(|&i| !self.spheres.x[i].iter().chain(&self.spheres.v[i]).all(|c| c.is_finite()))
            else {
                // Every value is finite but a distance overflowed: a sphere is absurdly fast.
                return Err(self.too_fast());
            };
            return Err(GraniteError::Unstable {
                step: self.step,
                time: self.time,
                reason: format!(
                    "non-finite position or velocity of sphere {} (x = {:?}, v = {:?}); the time step may be too large",
                    self.spheres.id.get(bad).copied().unwrap_or(0),
                    self.spheres.x.get(bad),
                    self.spheres.v.get(bad)
                ),
            });
        }
        if let Some(cell) = &mut self.cell {
            if let Some(m) = cell.flip_if_needed() {
                for s in self.pairs.shift.iter_mut() {
                    *s = shift_after_flip(&m, *s);
                }
                self.pairs.resort();
                self.needs_rebuild = true;
            }
        }
        let affine_growth = strain_since_build * (2.0 * self.radius_max_at_build + self.skin);
        if 2.0 * moved + affine_growth > self.skin || moved + wall_moved > self.skin {
            self.needs_rebuild = true;
        }
        Ok(())
    }

    /// The error of a step in which a sphere moved further than the smallest radius, naming the
    /// fastest sphere.
    fn too_fast(&self) -> GraniteError {
        let s = &self.spheres;
        let speed = |i: usize| s.v[i].iter().map(|c| c * c).sum::<f64>().sqrt();
        let fastest = (0..s.len()).max_by(|&i, &j| speed(i).total_cmp(&speed(j))).unwrap_or(0);
        let v = if s.is_empty() { 0.0 } else { speed(fastest) };
        let critical = self.critical_dt().map(|c| format!(" (critical_dt() = {c:.4e} s)")).unwrap_or_default();
        GraniteError::Unstable {
            step: self.step,
            time: self.time,
            reason: format!(
                "sphere {} moves at {v:.4e} m/s, {:.4e} m in one step of {:.4e} s: more than the smallest radius \
                 {:.4e} m, so contacts would be missed. The forces are too large for this time step: lower dt{critical}, \
                 or look for spheres placed overlapping or given such a velocity",
                s.id.get(fastest).copied().unwrap_or(0),
                v * self.dt,
                self.dt,
                self.radius_min_at_build
            ),
        }
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
            self.pairs.shrink_to_fit();
            self.wall_pairs.shrink_to_fit();
        }
    }

    /// Whether this step runs its stages in parallel pieces of consecutive spheres (and their
    /// pairs), rather than on the calling thread (an RVE, one thread, or too few spheres). Both
    /// make the same sums in the same order (see `write_back`).
    pub(crate) fn in_parallel(&self) -> bool {
        !self.sequential && self.spheres.len() >= MIN_SPHERES_IN_PARALLEL && rayon::current_num_threads() > 1
    }

    /// Sphere-sphere and sphere-wall contact forces of this step, summed into the spheres' loads
    /// on this thread (see [`DemSim::contacts_and_motion`] for the parallel step).
    fn contacts(&mut self) {
        let strides = (self.pairs.param_stride, self.pairs.history_stride);
        let Spheres { x, v, w, radius, force, torque, .. } = &mut self.spheres;
        let rotation = self.laws.iter().any(|l| l.resists_rotation());
        let sp = Motions { first: 0, x, v, w, radius, cell: self.cell.as_ref(), rotation };
        let mut scratch = ScratchGuard::take();
        let mut none = Handover::default();
        contact_job_wide(ContactJob {
            sp: &sp,
            walls: &self.walls,
            sphere_pairs: PairChunk::whole(&mut self.pairs, strides),
            wall_pairs: PairChunk::whole(&mut self.wall_pairs, strides),
            laws: &self.laws,
            dt: self.dt,
            scratch: &mut scratch,
            loads: Loads { first: 0, force, torque, handover: &mut none, starts: &[] },
        });
        debug_assert!(none.0.is_empty(), "one piece holds every pair");
    }

    /// The contact stage and the gather with the integration of a parallel step, in one pass
    /// (`par::run_pieces_then`): a piece's spheres move as soon as no contact piece that reads
    /// them is still running, so a worker done with its contacts moves spheres instead of waiting
    /// for the other's. The same sums in the same order as [`DemSim::contacts`] then
    /// `integrate`: see `write_back` and `gather_piece`. Returns the largest displacement (see
    /// `integrate`).
    fn contacts_and_motion(&mut self, motion: &Motion) -> f64 {
        let strides = (self.pairs.param_stride, self.pairs.history_stride);
        self.piece_bounds.refresh(self.spheres.len(), self.rebuilds, &self.pairs, &self.wall_pairs);
        let bounds = &self.piece_bounds;
        let starts = &bounds.spheres[..];
        let Spheres { x, v, w, radius, force, torque, mass, inertia, blocked, clump, .. } = &mut self.spheres;
        let rotation = self.laws.iter().any(|l| l.resists_rotation());
        let (x, v, w) = (SharedRows::new(x), SharedRows::new(v), SharedRows::new(w));
        let (walls, laws, dt, cell) = (&self.walls, &self.laws[..], self.dt, self.cell.as_ref());
        let n = starts.len() - 1;
        // Each piece borrows its own pairs, loads and handover in the worker that claims it. Cut
        // and lent from here, in slots that the workers then emptied, each step's descriptors
        // (some 350 bytes a piece) were written over cache lines the other core had last
        // written: 5-8 us of this serial setup in the 10k-sphere deposition on two threads.
        let (sphere_cuts, wall_cuts) = (&bounds.sphere_pairs[..], &bounds.wall_pairs[..]);
        let (sphere_list, wall_list) =
            (SharedPairs::new(&mut self.pairs, strides), SharedPairs::new(&mut self.wall_pairs, strides));
        let (force, torque) = (SharedRows::new(force), SharedRows::new(torque));
        let handovers = SharedRows::new(self.handovers.fit(n));
        let (mass, inertia, blocked, clump, x_at_build) =
            (&mass[..], &inertia[..], &blocked[..], &clump[..], &self.x_at_build[..]);
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
        self.piece_bounds.learn(&timings);
        moved.into_iter().map(|m| m.0).fold(0.0, farther)
    }

    /// Brings periodic positions back into the cell and fixes the shifts of their pairs.
    fn wrap_into_cell(&mut self) -> Result<()> {
        let Some(cell) = &self.cell else { return Ok(()) };
        let reach = 2.0 * self.spheres.largest_radius() + self.skin;
        let widths = cell.widths();
        if widths.iter().any(|&w| w < 2.0 * reach) {
            return Err(GraniteError::Setup(format!(
                "periodic cell too thin: its widths {widths:?} must be at least twice the interaction reach {reach:.4e} \
                 (largest diameter + skin)"
            )));
        }
        let inv = cell.inverse();
        let offset_of = |x: &Vec3| {
            let s = cell.reduced(&inv, *x);
            [s[0].floor() as i32, s[1].floor() as i32, s[2].floor() as i32]
        };
        let clump_offsets: Vec<[i32; 3]> = self.clumps.x.iter().map(offset_of).collect();
        let offsets: Vec<[i32; 3]> = (0..self.spheres.len())
            .map(|i| match self.spheres.clump[i] {
                FREE => offset_of(&self.spheres.x[i]),
                c => clump_offsets[c as usize],
            })
            .collect();
        if offsets.iter().all(|k| *k == [0; 3]) {
            return Ok(());
        }
        for (x, k) in self.clumps.x.iter_mut().zip(&clump_offsets) {
            let v = cell.shift_vector(*k);
            *x = sub(*x, v);
        }
        for (x, k) in self.spheres.x.iter_mut().zip(&offsets) {
            let v = cell.shift_vector(*k);
            *x = sub(*x, v);
        }
        let p = &mut self.pairs;
        for i in 0..p.len() {
            let (ka, kb) = (offsets[p.a[i] as usize], offsets[p.b[i] as usize]);
            for a in 0..3 {
                p.shift[i][a] += kb[a] - ka[a];
            }
        }
        p.resort();
        Ok(())
    }

    /// Numbers the spheres slab by slab across the longest side of the domain (then row by row;
    /// under gravity, across the longest side that is not the nearest to it),
    /// so that a parallel piece of spheres, and of the pairs sorted by their first sphere, is a
    /// region of space: its neighbours' data is mostly the piece's own, and stays in that core's
    /// cache. Done only before the first candidate lists exist (no pair to renumber), for systems
    /// large enough to run in several pieces, without clumps. Ids stay with their spheres.
    fn order_spheres_in_space(&mut self) {
        let n = self.spheres.len();
        if n < MIN_SPHERES_TO_ORDER || !self.clumps.is_empty() {
            return;
        }
        let reach = (2.0 * self.spheres.largest_radius() + self.skin).max(f64::MIN_POSITIVE);
        // Fractional position in the domain on each axis, and the domain's size.
        let (fraction, size): (Vec<Vec3>, Vec3) = match &self.cell {
            Some(cell) => {
                let inv = cell.inverse();
                let s = self.spheres.x.iter().map(|x| cell.reduced(&inv, *x).map(|c| c.rem_euclid(1.0))).collect();
                (s, cell.widths())
            }
            None => {
                let (lo, hi) = crate::math::point_bounds(&self.spheres.x);
                let size = [0, 1, 2].map(|a| (hi[a] - lo[a]).max(f64::MIN_POSITIVE));
                let s = self.spheres.x.iter().map(|x| [0, 1, 2].map(|a| (x[a] - lo[a]) / size[a])).collect();
                (s, size)
            }
        };
        if fraction.iter().flatten().any(|c| !c.is_finite()) {
            return;
        }
        let mut axes = [0, 1, 2];
        axes.sort_by(|&a, &b| size[b].total_cmp(&size[a]));
        // Under gravity the slabs stand along it, the axis nearest to it coming last: a settling
        // heap then puts a share of its bottom, where the contacts are, in every piece, and its
        // force chains, mostly along gravity, within pieces (a pair across pieces costs a store
        // and a gather; see `write_back`).
        let g = self.gravity;
        let down = (0..3).max_by(|&a, &b| g[a].abs().total_cmp(&g[b].abs())).filter(|&a| g[a] != 0.0);
        axes.sort_by_key(|&a| Some(a) == down);
        let cells = size.map(|l| ((l / reach) as u64).clamp(1, 1 << 20));
        let key = |f: &Vec3| axes.map(|a| ((f[a] * cells[a] as f64) as u64).min(cells[a] - 1));
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| key(&fraction[i]));
        self.spheres.permute(&order);
    }

    /// Merges `candidates` into `list` (see `PairList::merge`), giving each new pair the law of
    /// its two materials (the second a wall's if `wall`); returns a pair of materials without a
    /// contact law, if it met one.
    fn merge_pairs(
        &self,
        list: &mut PairList,
        spare: &mut PairList,
        candidates: &[Vec<Candidate>],
        strides: (usize, usize),
        wall: bool,
    ) -> Option<(u16, u16)> {
        // Pieces of at most MERGE_PIECE pairs (a periodic search hands over one sorted list).
        let pieces: Vec<&[Candidate]> = candidates.iter().flat_map(|b| b.chunks(MERGE_PIECE)).collect();
        let material = &self.spheres.material;
        let materials = |a: usize, b: usize| (material[a], if wall { self.walls[b].material } else { material[b] });
        let missing = list.merge(spare, &pieces, strides, self.in_parallel(), |a, b, law, params| {
            let (a, b) = (a as usize, b as usize);
            let pair = materials(a, b);
            let Some(l) = self.law_for(pair.0, pair.1) else { return false };
            *law = l;
            self.laws[l as usize].init_pair(&self.info_for(a, b, wall), params);
            true
        });
        missing.map(|(a, b)| materials(a as usize, b as usize))
    }

    /// Rebuilds the candidate pair lists (keeping the history of pairs still present).
    pub fn rebuild_candidates(&mut self) -> Result<()> {
        let (p_stride, h_stride) = self.pair_strides();
        if p_stride > MAX_PARAMS || h_stride > MAX_HISTORY {
            return Err(GraniteError::Setup(format!(
                "a contact law uses more than {MAX_PARAMS} parameters or {MAX_HISTORY} history values per contact"
            )));
        }
        self.wrap_into_cell()?;
        if self.pairs.is_empty() && self.wall_pairs.is_empty() {
            self.order_spheres_in_space();
        }
        let s = &self.spheres;
        let mut candidates = match &self.cell {
            Some(cell) => periodic_sphere_pairs(&s.x, &s.radius, self.skin, cell),
            None => sphere_pairs(&s.x, &s.radius, self.skin),
        };
        if !self.clumps.is_empty() {
            // Members of one clump never touch each other.
            for block in candidates.iter_mut() {
                block.retain(|&(a, b, _)| {
                    let ca = s.clump[a as usize];
                    ca == FREE || ca != s.clump[b as usize]
                });
            }
        }
        let mut pairs = std::mem::take(&mut self.pairs);
        // An RVE (sequential) rebuilds rarely and is copied into every material point: no spare.
        let mut spare = if self.sequential { PairList::default() } else { std::mem::take(&mut self.spare_pairs) };
        let mut wall_list = std::mem::take(&mut self.wall_pairs);
        let strides = (p_stride, h_stride);
        let mut merge_spheres = || self.merge_pairs(&mut pairs, &mut spare, &candidates, strides, false);
        let mut find_and_merge_walls = || {
            let wall_candidates = wall_pairs(&s.x, &s.radius, &self.walls, self.skin);
            self.merge_pairs(&mut wall_list, &mut PairList::default(), &wall_candidates, strides, true)
        };
        // Independent: side by side, the wall search and merge (0.3 ms in the 10k deposition)
        // keep a second worker busy while the sphere pairs' merge starts, and it then takes
        // pieces of that merge.
        let (missing_spheres, missing_walls) = if self.in_parallel() {
            rayon::join(merge_spheres, find_and_merge_walls)
        } else {
            (merge_spheres(), find_and_merge_walls())
        };
        let missing = missing_walls.or(missing_spheres);
        if let Some((a, b)) = missing {
            let name = |m: u16| self.materials.get(m as usize).map(|m| m.name.clone()).unwrap_or_default();
            return Err(GraniteError::Setup(format!(
                "no contact law for materials \"{}\" and \"{}\": give a default law or one for this pair",
                name(a),
                name(b)
            )));
        }
        self.pairs = pairs;
        if !self.sequential {
            self.spare_pairs = spare;
        }
        self.wall_pairs = wall_list;
        self.x_at_build = self.spheres.x.clone();
        self.walls_at_build = self.walls.iter().map(|w| w.position).collect();
        self.h_at_build = self.cell.as_ref().map(|c| c.h);
        self.radius_max_at_build = self.spheres.largest_radius();
        self.radius_min_at_build = self.spheres.smallest_radius();
        self.needs_rebuild = false;
        self.rebuilds += 1;
        Ok(())
    }
}

thread_local! {
    /// Scratch buffers are large (about 20 kB): keep one per thread across steps instead of
    /// allocating and zeroing one per step (that dominated small RVEs).
    static SCRATCH: std::cell::RefCell<Vec<Box<Scratch>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A scratch buffer borrowed from the thread's pool, returned on drop.
struct ScratchGuard(Option<Box<Scratch>>);

impl ScratchGuard {
    fn take() -> ScratchGuard {
        ScratchGuard(Some(SCRATCH.with(|p| p.borrow_mut().pop()).unwrap_or_else(Scratch::new)))
    }
}

impl std::ops::Deref for ScratchGuard {
    type Target = Scratch;
    fn deref(&self) -> &Scratch {
        self.0.as_deref().expect("scratch present until drop")
    }
}

impl std::ops::DerefMut for ScratchGuard {
    fn deref_mut(&mut self) -> &mut Scratch {
        self.0.as_deref_mut().expect("scratch present until drop")
    }
}

impl Drop for ScratchGuard {
    fn drop(&mut self) {
        if let Some(s) = self.0.take() {
            SCRATCH.with(|p| p.borrow_mut().push(s));
        }
    }
}

/// Touching contacts of one chunk, compacted for the law call.
struct Scratch {
    /// Pair of each contact in its chunk.
    slot: [u32; CHUNK],
    law: [u16; CHUNK],
    normal: [Vec3; CHUNK],
    overlap: [f64; CHUNK],
    rel_velocity: [Vec3; CHUNK],
    rel_spin: [Vec3; CHUNK],
    /// Distances from the two centres to the contact point along the normal (the lever arms
    /// of the force; the second is 0 for walls).
    lever: [[f64; 2]; CHUNK],
    force: [Vec3; CHUNK],
    moment: [Vec3; CHUNK],
    len: usize,
    /// Whether relative spins and contact moments are computed (see `Motions::rotation`).
    rotation: bool,
}

/// The per-pair parameters and history of a chunk, and values per pair.
struct PairState<'c> {
    params: &'c [f64],
    history: &'c mut [f64],
    strides: (usize, usize),
}

impl Scratch {
    fn new() -> Box<Scratch> {
        Box::new(Scratch {
            slot: [0; CHUNK],
            law: [0; CHUNK],
            normal: [[0.0; 3]; CHUNK],
            overlap: [0.0; CHUNK],
            rel_velocity: [[0.0; 3]; CHUNK],
            rel_spin: [[0.0; 3]; CHUNK],
            lever: [[0.0; 2]; CHUNK],
            force: [[0.0; 3]; CHUNK],
            moment: [[0.0; 3]; CHUNK],
            len: 0,
            rotation: true,
        })
    }

    /// One law call on the first `n` contacts.
    fn call(&mut self, law: &dyn ContactLaw, n: usize, dt: f64, state: &mut PairState<'_>) {
        law.compute(ContactBatch {
            normal: &self.normal[..n],
            overlap: &self.overlap[..n],
            rel_velocity: &self.rel_velocity[..n],
            rel_spin: &self.rel_spin[..if self.rotation { n } else { 0 }],
            slot: &self.slot[..n],
            strides: state.strides,
            params: state.params,
            history: state.history,
            force: &mut self.force[..n],
            moment: &mut self.moment[..if self.rotation { n } else { 0 }],
            dt,
        });
    }

    /// Calls each law present on its contacts: one call on the chunk when it has a single law,
    /// otherwise each law on its own compacted subset. Laws update their pairs' history in place.
    fn run_laws(&mut self, laws: &[Arc<dyn ContactLaw>], dt: f64, mut state: PairState<'_>) {
        let n = self.len;
        if n == 0 {
            return;
        }
        let first = self.law[0];
        if self.law[..n].iter().all(|&l| l == first) {
            self.call(laws[first as usize].as_ref(), n, dt, &mut state);
            return;
        }
        // A second scratch buffer from the thread's pool: no allocation per chunk.
        let mut sub = ScratchGuard::take();
        sub.rotation = self.rotation;
        let mut done = [false; CHUNK];
        let mut members = [0usize; CHUNK];
        for k in 0..n {
            if done[k] {
                continue;
            }
            let l = self.law[k];
            let mut count = 0;
            for m in (k..n).filter(|&m| self.law[m] == l) {
                members[count] = m;
                count += 1;
            }
            let members = &members[..count];
            for (s, &m) in members.iter().enumerate() {
                sub.slot[s] = self.slot[m];
                sub.normal[s] = self.normal[m];
                sub.overlap[s] = self.overlap[m];
                sub.rel_velocity[s] = self.rel_velocity[m];
                sub.rel_spin[s] = self.rel_spin[m];
            }
            sub.call(laws[l as usize].as_ref(), members.len(), dt, &mut state);
            for (s, &m) in members.iter().enumerate() {
                self.force[m] = sub.force[s];
                self.moment[m] = sub.moment[s];
                done[m] = true;
            }
        }
    }
}

/// What the contact stage reads of the spheres.
struct Motions<'a> {
    /// The sphere in the first row of these arrays (sphere `i` is row `i - first`).
    first: usize,
    x: &'a [Vec3],
    v: &'a [Vec3],
    w: &'a [Vec3],
    radius: &'a [f64],
    /// The periodic cell: images and the affine velocity field across it.
    cell: Option<&'a PeriodicCell>,
    /// Whether some contact law resists relative rotation (else spins and moments are skipped).
    rotation: bool,
}

/// The loads (force and torque sums) of a run of consecutive spheres from sphere `first`, which
/// the contact stage adds its forces to: all spheres when stepping sequentially, a parallel
/// piece's otherwise.
struct Loads<'a> {
    first: usize,
    force: &'a mut [Vec3],
    torque: &'a mut [Vec3],
    /// The loads of pairs whose second sphere lies before `first`, for the gather.
    handover: &'a mut Handover,
    /// The first sphere of each parallel piece, then the sphere count: where to hand loads over.
    starts: &'a [usize],
}

/// A load handed over: the second sphere of a pair, the force on its first sphere and the torque
/// on the second.
type HandedLoad = (u32, Vec3, Vec3);

/// The loads of one parallel piece's touching pairs whose second sphere lies in an earlier piece:
/// the last terms of those spheres' sums (see `write_back`), which the contact stage hands over
/// to the gather. One list per earlier piece, each in pair order (so each sphere's loads are),
/// which that piece's gather reads whole. Filled anew every step.
#[derive(Debug, Default)]
pub(crate) struct Handover(Vec<Vec<HandedLoad>>);

impl Handover {
    /// Empties the lists for the `earlier` pieces before this one, keeping their storage.
    fn start(&mut self, earlier: usize) {
        self.0.resize_with(earlier, Vec::new);
        self.0.iter_mut().for_each(Vec::clear);
    }

    #[inline(always)]
    fn push(&mut self, piece: usize, sphere: usize, force: Vec3, torque: Vec3) {
        self.0[piece].push((sphere as u32, force, torque));
    }

    /// The loads handed over to the spheres of `piece`, in pair order.
    fn to(&self, piece: usize) -> &[HandedLoad] {
        &self.0[piece]
    }
}

/// One [`Handover`] per parallel piece, kept from step to step for their storage.
#[derive(Debug, Default)]
pub(crate) struct Handovers(Vec<Handover>);

impl Clone for Handovers {
    /// Handovers live within a step: a copy starts with none.
    fn clone(&self) -> Handovers {
        Handovers::default()
    }
}

impl Handovers {
    /// One per piece, in piece order.
    fn fit(&mut self, pieces: usize) -> &mut [Handover] {
        self.0.resize_with(pieces, Handover::default);
        &mut self.0
    }

    pub(crate) fn bytes(&self) -> usize {
        let lists = self.0.iter().flat_map(|h| &h.0);
        lists.map(|l| l.capacity() * std::mem::size_of::<HandedLoad>()).sum::<usize>()
            + self.0.iter().map(|h| h.0.capacity() * std::mem::size_of::<Vec<HandedLoad>>()).sum::<usize>()
    }
}

impl Loads<'_> {
    /// Where sphere `i` is in this run, if it is in it.
    #[inline(always)]
    fn index(&self, i: usize) -> Option<usize> {
        let k = i.wrapping_sub(self.first);
        (k < self.force.len()).then_some(k)
    }

    /// Hands a pair's loads over to its second sphere `j`, which lies in an earlier piece.
    #[inline(always)]
    fn hand_over(&mut self, j: usize, force: Vec3, torque: Vec3) {
        let piece = self.starts.partition_point(|&s| s <= j) - 1;
        self.handover.push(piece, j, force, torque);
    }
}

/// The per-pair arrays of a run of consecutive pairs of a pair list.
struct PairChunk<'a> {
    /// Index of the first pair in the whole list.
    first: usize,
    strides: (usize, usize),
    a: &'a [u32],
    b: &'a [u32],
    shift: &'a [[i32; 3]],
    law: &'a [u16],
    params: &'a [f64],
    history: &'a mut [f64],
    touching: &'a mut [bool],
    force: &'a mut [Vec3],
}

impl<'a> PairChunk<'a> {
    fn whole(p: &'a mut PairList, strides: (usize, usize)) -> PairChunk<'a> {
        PairChunk {
            first: 0,
            strides,
            a: &p.a,
            b: &p.b,
            shift: &p.shift,
            law: &p.law,
            params: &p.params,
            history: &mut p.history,
            touching: &mut p.touching,
            force: &mut p.force,
        }
    }

    fn len(&self) -> usize {
        self.a.len()
    }

    fn state(&mut self) -> PairState<'_> {
        PairState { params: self.params, history: self.history, strides: self.strides }
    }

    /// The first `mid` pairs and the rest.
    fn split_at(self, mid: usize) -> (PairChunk<'a>, PairChunk<'a>) {
        let (ps, hs) = self.strides;
        let (a, a2) = self.a.split_at(mid);
        let (b, b2) = self.b.split_at(mid);
        let (shift, shift2) = self.shift.split_at(mid);
        let (law, law2) = self.law.split_at(mid);
        let (params, params2) = self.params.split_at(mid * ps);
        let (history, history2) = self.history.split_at_mut(mid * hs);
        let (touching, touching2) = self.touching.split_at_mut(mid);
        let (force, force2) = self.force.split_at_mut(mid);
        let strides = self.strides;
        (
            PairChunk { first: self.first, strides, a, b, shift, law, params, history, touching, force },
            PairChunk {
                first: self.first + mid,
                strides,
                a: a2,
                b: b2,
                shift: shift2,
                law: law2,
                params: params2,
                history: history2,
                touching: touching2,
                force: force2,
            },
        )
    }

    /// Takes the next run of at most `CHUNK` pairs off the front of `rest` (None when empty).
    #[inline(always)]
    fn next_chunk(rest: &mut Option<PairChunk<'a>>) -> Option<PairChunk<'a>> {
        let all = rest.take()?;
        if all.len() == 0 {
            return None;
        }
        let mid = CHUNK.min(all.len());
        let (head, tail) = all.split_at(mid);
        *rest = Some(tail);
        Some(head)
    }
}

/// The pairs of piece `q`: between the cuts before and after it (`cuts` holds the first pair of
/// every piece after the first; the last piece ends at `total`).
fn piece_range(cuts: &[usize], total: usize, q: usize) -> Range<usize> {
    let start = if q == 0 { 0 } else { cuts[q - 1] };
    start..cuts.get(q).copied().unwrap_or(total)
}

/// A pair list lent to a parallel pass: what the pass only reads, shared; what it writes (the
/// history, the contact flags and the forces), as rows that each piece borrows for its own pairs.
struct SharedPairs<'a> {
    strides: (usize, usize),
    a: &'a [u32],
    b: &'a [u32],
    shift: &'a [[i32; 3]],
    law: &'a [u16],
    params: &'a [f64],
    history: SharedRows<'a, f64>,
    touching: SharedRows<'a, bool>,
    force: SharedRows<'a, Vec3>,
}

impl<'a> SharedPairs<'a> {
    fn new(list: &'a mut PairList, strides: (usize, usize)) -> SharedPairs<'a> {
        let PairList { a, b, shift, law, params, history, touching, force, .. } = list;
        SharedPairs {
            strides,
            a,
            b,
            shift,
            law,
            params,
            history: SharedRows::new(history),
            touching: SharedRows::new(touching),
            force: SharedRows::new(force),
        }
    }

    fn len(&self) -> usize {
        self.a.len()
    }

    /// The pairs `range`, their history, flags and forces to change; panics when out of range.
    ///
    /// # Safety
    /// While the chunk is used, no other chunk of an overlapping range may be.
    unsafe fn chunk(&self, range: Range<usize>) -> PairChunk<'a> {
        let (ps, hs) = self.strides;
        PairChunk {
            first: range.start,
            strides: self.strides,
            a: &self.a[range.clone()],
            b: &self.b[range.clone()],
            shift: &self.shift[range.clone()],
            law: &self.law[range.clone()],
            params: &self.params[range.start * ps..range.end * ps],
            // SAFETY: these rows are this chunk's alone, by the caller's promise.
            history: unsafe { self.history.piece(range.start * hs..range.end * hs) },
            touching: unsafe { self.touching.piece(range.clone()) },
            force: unsafe { self.force.piece(range) },
        }
    }
}

/// Writes the law results of a chunk back to its pairs, with lever-arm torques, and adds them to
/// the spheres' loads. Each sphere's loads are summed in one order on any number of threads:
/// - its walls, in pair order, from zero (the contact stage does them first);
/// - its sphere pairs in pair order: since pairs are sorted by their first sphere and the second
///   is the smaller index, its own pairs come first; they are summed apart from zero (`run`,
///   carried from chunk to chunk) and added when they end, and then each pair in which it is
///   second is added in turn.
///
/// A parallel piece holds the pairs whose first sphere is among its spheres, and each piece's
/// pairs come before those of the pieces after it. So the pairs of a sphere not yet added when
/// its piece is done are those whose first sphere is in a later piece: the last ones in this
/// order. The piece hands their loads over to the gather, which adds them after the contact stage
/// (see `gather_piece`). Wall pairs have no second sphere (`second` false).
#[inline(always)]
fn write_back(c: &mut PairChunk<'_>, s: &Scratch, loads: &mut Loads<'_>, second: bool, run: Run) -> Run {
    if s.rotation {
        write_back_as::<true>(c, s, loads, second, run)
    } else {
        write_back_as::<false>(c, s, loads, second, run)
    }
}

/// [`write_back`], with or without contact moments (without, the laws left them unset: adding
/// zeros would only cost).
#[inline(always)]
fn write_back_as<const MOMENTS: bool>(
    c: &mut PairChunk<'_>,
    s: &Scratch,
    loads: &mut Loads<'_>,
    second: bool,
    mut run: Run,
) -> Run {
    for e in 0..s.len {
        let k = s.slot[e] as usize;
        let f = s.force[e];
        c.force[k] = f;
        // The force acts at la n from the first centre and -lb n from the second.
        let [la, lb] = s.lever[e];
        let nf = cross(s.normal[e], f);
        let (mut torque_a, mut torque_b) = ([la * nf[0], la * nf[1], la * nf[2]], [lb * nf[0], lb * nf[1], lb * nf[2]]);
        if MOMENTS {
            let m = s.moment[e];
            (torque_a, torque_b) = (add(torque_a, m), sub(torque_b, m));
        }
        let i = c.a[k] as usize;
        if i != run.sphere {
            run = run.finish(loads, second, i);
        }
        run.force = add(run.force, f);
        run.torque = add(run.torque, torque_a);
        if second {
            match loads.index(c.b[k] as usize) {
                Some(j) => {
                    loads.force[j] = sub(loads.force[j], f);
                    loads.torque[j] = add(loads.torque[j], torque_b);
                }
                None => loads.hand_over(c.b[k] as usize, f, torque_b),
            }
        }
    }
    run
}

/// A sphere's running force and torque sums over a run of consecutive pairs (pairs are sorted by
/// their first sphere), kept in registers: adding each force to memory would make every contact
/// wait for the previous one's store.
struct Run {
    sphere: usize,
    force: Vec3,
    torque: Vec3,
}

impl Run {
    /// No sphere yet.
    const NONE: Run = Run { sphere: usize::MAX, force: [0.0; 3], torque: [0.0; 3] };

    /// Ends this run and starts `next`'s from zero: see [`Run::end`].
    #[inline(always)]
    fn finish(&self, loads: &mut Loads<'_>, add_on: bool, next: usize) -> Run {
        self.end(loads, add_on);
        Run { sphere: next, force: [0.0; 3], torque: [0.0; 3] }
    }

    /// Adds the sums to the sphere's loads (`add_on`: sphere pairs), or stores them (walls, which
    /// come first: from zero either way, and a store does not wait for the loads to be read).
    #[inline(always)]
    fn end(&self, loads: &mut Loads<'_>, add_on: bool) {
        if self.sphere == usize::MAX {
            return;
        }
        let i = self.sphere - loads.first;
        if add_on {
            loads.force[i] = add(loads.force[i], self.force);
            loads.torque[i] = add(loads.torque[i], self.torque);
        } else {
            (loads.force[i], loads.torque[i]) = (self.force, self.torque);
        }
    }
}

/// Marks a pair apart.
#[inline(always)]
fn open_contact(c: &mut PairChunk<'_>, k: usize) {
    // Pairs that were already apart are clean: skip the writes (most candidates, most steps).
    if !c.touching[k] {
        return;
    }
    c.touching[k] = false;
    c.force[k] = [0.0; 3];
    let hs = c.strides.1;
    c.history[k * hs..(k + 1) * hs].iter_mut().for_each(|h| *h = 0.0);
}

/// The contact stage on a run of pairs: all of them (sequential stepping, forces summed into
/// `sums` as they come), or one parallel piece.
struct ContactJob<'j> {
    sp: &'j Motions<'j>,
    walls: &'j [Wall],
    sphere_pairs: PairChunk<'j>,
    wall_pairs: PairChunk<'j>,
    laws: &'j [Arc<dyn ContactLaw>],
    dt: f64,
    scratch: &'j mut Scratch,
    /// The loads of the run's spheres (those the pairs start from), summed anew.
    loads: Loads<'j>,
}

#[inline(always)]
fn contact_job(job: ContactJob<'_>) {
    let ContactJob { sp, walls, sphere_pairs, wall_pairs, laws, dt, scratch, mut loads } = job;
    loads.force.fill([0.0; 3]);
    loads.torque.fill([0.0; 3]);
    // Walls first: see `write_back`.
    wall_contacts(sp, walls, wall_pairs, (laws, dt), scratch, &mut loads);
    sphere_contacts(sp, sphere_pairs, (laws, dt), scratch, &mut loads);
}

crate::wide_kernel!(fn contact_job_wide(job: ContactJob<'_>) => contact_job);

/// Sphere-sphere geometry (`sphere_sphere`) and contact forces; in a periodic cell the second
/// sphere may be an image, whose velocity includes the affine field across the cell.
#[inline(always)]
fn sphere_contacts(
    sp: &Motions<'_>,
    pairs: PairChunk<'_>,
    (laws, dt): (&[Arc<dyn ContactLaw>], f64),
    scratch: &mut Scratch,
    loads: &mut Loads<'_>,
) {
    let cell = sp.cell;
    let l = cell.map(|c| c.velocity_gradient);
    // Sliced to one length: checking a row against one array then covers the others.
    let rows = sp.x.len();
    let (x, v, w, radius) = (&sp.x[..rows], &sp.v[..rows], &sp.w[..rows], &sp.radius[..rows]);
    let first = sp.first;
    // Plain loops, no closures: all of this must inline into `contact_job_wide`'s AVX2 twin.
    let mut rest = Some(pairs);
    let mut run = Run::NONE;
    while let Some(mut chunk) = PairChunk::next_chunk(&mut rest) {
        let (c, s) = (&mut chunk, &mut *scratch);
        // The count of touching contacts stays in a register: in `s.len` every contact would wait
        // for the previous one to store it.
        let mut len = 0;
        s.rotation = sp.rotation;
        let m = c.a.len();
        let (a, b, shift, law) = (&c.a[..m], &c.b[..m], &c.shift[..m], &c.law[..m]);
        for k in 0..m {
            let (i, j) = ((a[k] as usize).wrapping_sub(first), (b[k] as usize).wrapping_sub(first));
            let d = branch(x, i, j, shift[k], cell);
            let reach = radius[i] + radius[j];
            let dist2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if dist2 >= reach * reach {
                open_contact(c, k);
                continue;
            }
            // 1/dist as dist/dist2: the root and the division run side by side, not one after
            // the other.
            let inv2 = 1.0 / dist2;
            let dist = dist2.sqrt();
            let inv = dist * inv2;
            let n = [d[0] * inv, d[1] * inv, d[2] * inv];
            let overlap = reach - dist;
            let la = radius[i] - 0.5 * overlap;
            // Contact point velocities v_a + w_a x (la n) and v_b + w_b x (-lb n), lb = dist - la:
            // one cross product for both spins.
            let lb = dist - la;
            let spins = [la * w[i][0] + lb * w[j][0], la * w[i][1] + lb * w[j][1], la * w[i][2] + lb * w[j][2]];
            let mut rel_velocity = sub(sub(v[j], v[i]), cross(spins, n));
            if let Some(l) = &l {
                // Affine part of the relative velocity: L (x_b + h n - x_a).
                rel_velocity = add(rel_velocity, mat_vec(l, d));
            }
            c.touching[k] = true;
            let e = len;
            s.slot[e] = k as u32;
            s.law[e] = law[k];
            s.normal[e] = n;
            s.overlap[e] = overlap;
            s.rel_velocity[e] = rel_velocity;
            if sp.rotation {
                s.rel_spin[e] = sub(w[j], w[i]);
            }
            s.lever[e] = [la, lb];
            len += 1;
        }
        s.len = len;
        s.run_laws(laws, dt, c.state());
        run = write_back(c, s, loads, true, run);
    }
    run.end(loads, true);
}

/// Sphere-wall geometry and contact forces (the wall is particle 2, infinitely heavy).
#[inline(always)]
fn wall_contacts(
    sp: &Motions<'_>,
    walls: &[Wall],
    pairs: PairChunk<'_>,
    (laws, dt): (&[Arc<dyn ContactLaw>], f64),
    scratch: &mut Scratch,
    loads: &mut Loads<'_>,
) {
    // Plain loops, no closures: all of this must inline into `contact_job_wide`'s AVX2 twin.
    let mut rest = Some(pairs);
    let mut run = Run::NONE;
    while let Some(mut chunk) = PairChunk::next_chunk(&mut rest) {
        let (c, s) = (&mut chunk, &mut *scratch);
        let mut len = 0;
        s.rotation = sp.rotation;
        for k in 0..c.a.len() {
            let (i, w) = ((c.a[k] as usize).wrapping_sub(sp.first), c.b[k] as usize);
            let wall = &walls[w];
            let geo = match wall.contact(sp.x[i], sp.radius[i], 0.0) {
                Some(g) if g.gap < 0.0 => g,
                _ => {
                    open_contact(c, k);
                    continue;
                }
            };
            let overlap = -geo.gap;
            let arm_a = sub(geo.point, sp.x[i]);
            let va = add(sp.v[i], cross(sp.w[i], arm_a));
            c.touching[k] = true;
            let e = len;
            s.slot[e] = k as u32;
            s.law[e] = c.law[k];
            s.normal[e] = geo.normal;
            s.overlap[e] = overlap;
            s.rel_velocity[e] = sub(wall.velocity, va);
            if sp.rotation {
                s.rel_spin[e] = [-sp.w[i][0], -sp.w[i][1], -sp.w[i][2]];
            }
            s.lever[e] = [dot3(arm_a, geo.normal), 0.0];
            len += 1;
        }
        s.len = len;
        s.run_laws(laws, dt, c.state());
        run = write_back(c, s, loads, false, run);
    }
    run.end(loads, false);
}

/// Branch vector from sphere `i` to sphere `j` (or its periodic image `shift`).
#[inline(always)]
pub(crate) fn branch(x: &[Vec3], i: usize, j: usize, shift: [i32; 3], cell: Option<&PeriodicCell>) -> Vec3 {
    let image = match (cell, shift) {
        (Some(cell), n) if n != [0; 3] => cell.shift_vector(n),
        _ => [0.0; 3],
    };
    add(sub(x[j], x[i]), image)
}

/// Where the parallel stages cut the spheres and the pair lists: into pieces of consecutive
/// spheres with the pairs whose first spheres fall in them (pairs are sorted by first sphere), so
/// a worker mostly sums forces it computed itself, from its own cache. Found again when the lists
/// are rebuilt, the piece count changes, or the workers' speeds drift apart; any cuts give the
/// same forces.
#[derive(Debug, Clone, Default)]
pub(crate) struct PieceBounds {
    /// Sphere count, piece count, rebuild count and list lengths the cuts were found for.
    key: (usize, usize, u64, usize, usize),
    /// The first sphere of each piece, then the sphere count.
    spheres: Vec<usize>,
    /// Where each piece after the first starts in the pair lists.
    sphere_pairs: Vec<usize>,
    wall_pairs: Vec<usize>,
    /// For each piece, the first piece holding a sphere it reads (the second spheres of its pairs
    /// lie before their first): its contacts read the spheres of pieces `reads_from[q]..=q`.
    reads_from: Vec<usize>,
    /// Units of work of each piece (see [`PieceBounds::refresh`]).
    units: Vec<usize>,
    /// Each worker's share of the work the cuts were made for.
    shares: Vec<f64>,
    /// What the steps since taught of the workers' speeds, and how many steps ago the cuts were
    /// made.
    speeds: crate::par::WorkerSpeeds,
    age: u64,
}

/// A worker's share of the work that has to drift this far from the one the pieces were cut for
/// before they are cut again, and the steps that have to pass: recutting costs a pass over the
/// pair list (a few microseconds in a 1500-sphere RVE), and the speeds' estimates are noisy.
const RECUT_DRIFT: f64 = 0.01;
const RECUT_AFTER_STEPS: u64 = 10;
/// Most pieces a worker may hold for the cuts to follow the workers' speeds (see `refresh`).
const BALANCE_UP_TO_PIECES_PER_WORKER: usize = 3;

impl PieceBounds {
    /// Cuts into pieces that give each worker its share of the work (equal until the workers'
    /// speeds are known, see `par::WorkerSpeeds`), counting one unit for each candidate pair (the
    /// contact stage) and one for each sphere (the gather): in the periodic RVE a candidate costs
    /// about 220 instructions a step and a sphere's integration 160 (callgrind). Equal sphere
    /// counts would not do: in a periodic cell the pairs that wrap round it belong to the last
    /// spheres (pairs are stored under their larger index), whose piece then held twice the
    /// pairs of the first.
    fn refresh(&mut self, spheres: usize, rebuilds: u64, pairs: &PairList, walls: &PairList) {
        let pieces = crate::par::piece_count(spheres, MIN_SPHERES_PER_PIECE);
        let key = (spheres, pieces, rebuilds, pairs.len(), walls.len());
        let workers = crate::par::workers_for(pieces);
        // A worker that holds many pieces takes over others' when it is ahead: the stage balances
        // itself (see `par`), and shares learnt from pieces of uneven cost would only move data
        // between the cores (in the 10k-sphere deposition, 13 pieces a worker, they swung between
        // 0.2 and 0.8 and made the step 3-10 % slower).
        let shares = if pieces <= BALANCE_UP_TO_PIECES_PER_WORKER * workers {
            self.speeds.shares(workers)
        } else {
            vec![1.0 / workers as f64; workers]
        };
        let drifted = shares.iter().zip(&self.shares).any(|(now, cut)| (now - cut).abs() > RECUT_DRIFT);
        self.age += 1;
        let stale = key != self.key || shares.len() != self.shares.len();
        let due = drifted && self.age >= RECUT_AFTER_STEPS;
        if !(stale || due) {
            return;
        }
        let owners = crate::par::owners(pieces);
        let fractions = crate::par::piece_starts(&owners, &shares);
        let before = |list: &PairList, s: usize| list.a.partition_point(|&a| (a as usize) < s);
        let work_before = |s: usize| s + before(pairs, s) + before(walls, s);
        let total = work_before(spheres);
        let mut starts = vec![0];
        for &fraction in &fractions[1..pieces] {
            let target = (total as f64 * fraction).round() as usize;
            // The first sphere with at least `target` work before it (work grows with s).
            let from = *starts.last().unwrap_or(&0);
            starts.push(crate::math::partition_index(from..spheres, |s| work_before(s) < target));
        }
        starts.push(spheres);
        let cuts = |list: &PairList| starts[1..pieces].iter().map(|&s| before(list, s)).collect::<Vec<_>>();
        let sphere_pairs = cuts(pairs);
        let piece_of = |sphere: usize| starts.partition_point(|&s| s <= sphere) - 1;
        let reads_from = (0..pieces)
            .map(|q| {
                let (from, to) =
                    (if q == 0 { 0 } else { sphere_pairs[q - 1] }, sphere_pairs.get(q).copied().unwrap_or(pairs.len()));
                pairs.b[from..to].iter().min().map_or(q, |&b| piece_of(b as usize)).min(q)
            })
            .collect();
        let units = starts.windows(2).map(|w| work_before(w[1]) - work_before(w[0])).collect();
        let speeds = std::mem::take(&mut self.speeds);
        *self = PieceBounds {
            key,
            sphere_pairs,
            wall_pairs: cuts(walls),
            spheres: starts,
            reads_from,
            units,
            shares,
            speeds,
            age: 0,
        };
    }

    /// Learns the workers' speeds from the time each piece's two stages took, on the workers that
    /// ran them (`(worker, seconds)` for the contacts, then for the motion of each piece).
    fn learn(&mut self, timed: &[[(usize, f64); 2]]) {
        let workers = self.shares.len();
        let spheres = |p: usize| self.spheres[p + 1] - self.spheres[p];
        let samples = timed.iter().enumerate().flat_map(|(p, [contacts, motion])| {
            [(contacts.0, (self.units[p] - spheres(p)) as f64, contacts.1), (motion.0, spheres(p) as f64, motion.1)]
        });
        self.speeds.learn(workers, samples);
    }

    pub(crate) fn bytes(&self) -> usize {
        (self.spheres.capacity()
            + self.sphere_pairs.capacity()
            + self.wall_pairs.capacity()
            + self.reads_from.capacity()
            + self.units.capacity())
            * std::mem::size_of::<usize>()
            + (self.shares.capacity() + self.speeds.workers()) * std::mem::size_of::<f64>()
    }
}

/// One parallel piece of the force gather with the integration: consecutive spheres from
/// `first` (piece number `part`), their state (`moving`), what stays fixed over the step and the
/// handovers of the pieces after this one.
struct GatherJob<'j> {
    first: usize,
    part: usize,
    moving: PieceState<'j>,
    fixed: SphereConstants<'j>,
    later: &'j [&'j Handover],
    motion: &'j Motion,
}

/// The state a piece's spheres change in a step (their run of each array).
struct PieceState<'j> {
    x: &'j mut [Vec3],
    v: &'j mut [Vec3],
    w: &'j mut [Vec3],
    force: &'j mut [Vec3],
    torque: &'j mut [Vec3],
}

/// What a step reads of every sphere and leaves as it is.
struct SphereConstants<'j> {
    mass: &'j [f64],
    inertia: &'j [f64],
    blocked: &'j [u8],
    clump: &'j [u32],
    x_at_build: &'j [Vec3],
}

/// Adds the loads handed over to a piece's spheres, then moves them.
fn gather_piece(job: GatherJob<'_>) -> f64 {
    let GatherJob { first, part, moving, fixed, later, motion } = job;
    // The last terms of `write_back`'s order: piece after piece, each in pair order.
    for h in later {
        for &(i, f, t) in h.to(part) {
            let k = i as usize - first;
            moving.force[k] = sub(moving.force[k], f);
            moving.torque[k] = add(moving.torque[k], t);
        }
    }
    move_run_wide((first, moving, &fixed, motion))
}

/// Whether none of these spheres has a blocked degree of freedom or belongs to a clump: their
/// integration then needs no per-sphere test (most scenes; one pass over two small arrays).
#[inline(always)]
fn all_free(blocked: &[u8], clump: &[u32]) -> bool {
    blocked.iter().fold(0, |any, &b| any | b) == 0 && clump.iter().all(|&c| c == FREE)
}

/// The larger of two displacements, NaN if either is (`f64::max` would drop a NaN, and with it
/// the news that some state stopped being finite).
fn farther(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Leapfrog integration with gravity and Cundall damping, on the calling thread. In a periodic
/// cell (`affine` = `(L, F)`) velocities are fluctuations and positions also follow the affine
/// field `L x`. Returns the largest displacement since the candidate lists were built, not
/// counting the affine part `F x_build` (NaN if a sphere's state stopped being finite).
fn integrate(sp: &mut Spheres, x_at_build: &[Vec3], motion: &Motion) -> f64 {
    let Spheres { x, v, w, mass, inertia, force, torque, blocked, clump, .. } = sp;
    let moving = PieceState { x, v, w, force, torque };
    let fixed = SphereConstants { mass, inertia, blocked, clump, x_at_build };
    move_run_wide((0, moving, &fixed, motion))
}

/// Moves the spheres of a run that starts at sphere `first` (see [`integrate_run`]) and returns
/// the largest displacement (see [`integrate`]).
#[inline(always)]
fn move_run((first, moving, fixed, motion): (usize, PieceState<'_>, &SphereConstants<'_>, &Motion)) -> f64 {
    let range = first..first + moving.x.len();
    if all_free(&fixed.blocked[range.clone()], &fixed.clump[range]) {
        integrate_run::<true>(first, moving, fixed, motion).largest()
    } else {
        integrate_run::<false>(first, moving, fixed, motion).largest()
    }
}

// The kernel returns a number, not the running record (`Travel`): the parallel gather's kernel
// returned the record, and there the compiler split every four-lane operation of the loop in two
// (184 instructions a sphere against 155, callgrind).
crate::wide_kernel!(fn move_run_wide(job: (usize, PieceState<'_>, &SphereConstants<'_>, &Motion)) -> f64 => move_run);

/// Moves the spheres of a run that starts at sphere `first`, under the loads in its `force` and
/// `torque`.
#[inline(always)]
fn integrate_run<const ALL_FREE: bool>(
    first: usize,
    PieceState { x, v, w, force, torque }: PieceState<'_>,
    fixed: &SphereConstants<'_>,
    motion: &Motion,
) -> Travel {
    let n = x.len();
    let range = first..first + n;
    let (v, w, force, torque) = (&mut v[..n], &mut w[..n], &force[..n], &torque[..n]);
    let (mass, inertia) = (&fixed.mass[range.clone()], &fixed.inertia[range.clone()]);
    let (blocked, clump, x_at_build) =
        (&fixed.blocked[range.clone()], &fixed.clump[range.clone()], &fixed.x_at_build[range]);
    let mut travel = Travel::default();
    for i in 0..n {
        let (moved2, state) = motion.advance_as::<ALL_FREE>(
            (&mut x[i], &mut v[i], &mut w[i]),
            (mass[i], inertia[i], blocked[i], clump[i]),
            (widen(force[i]), widen(torque[i])),
            &x_at_build[i],
        );
        travel.record(moved2, state);
    }
    travel
}

/// What moves every free sphere in one step.
struct Motion {
    gravity: Vec3,
    damping: f64,
    dt: f64,
    affine: Option<(Matrix3<f64>, Matrix3<f64>)>,
    /// `gravity` and the columns of `affine`'s `(L, F, L dt)` as lanes.
    gravity_lanes: Lanes,
    affine_columns: Option<([Lanes; 3], [Lanes; 3], [Lanes; 3])>,
}

impl Motion {
    fn new(gravity: Vec3, damping: f64, dt: f64, affine: Option<(Matrix3<f64>, Matrix3<f64>)>) -> Motion {
        let affine_columns =
            affine.as_ref().map(|(l, f)| (simd::columns(l), simd::columns(f), simd::columns(&(l * dt))));
        Motion { gravity, damping, dt, affine, gravity_lanes: simd::widen(gravity), affine_columns }
    }

    /// [`Motion::advance`], or [`Motion::advance_free`] when the caller knows `ALL_FREE` spheres
    /// (not blocked, not clumped).
    #[inline(always)]
    fn advance_as<const ALL_FREE: bool>(
        &self,
        sphere: (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia, blocked, clump): (f64, f64, u8, u32),
        loads: (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        if ALL_FREE {
            self.advance_free(sphere, (m, inertia), loads, x0)
        } else {
            self.advance(sphere, (m, inertia, blocked, clump), loads, x0)
        }
    }

    /// Moves one sphere. Returns what [`Travel::record`] takes: its squared displacement since
    /// the build and its state to check. Returned rather than recorded through a reference, so
    /// that the running record stays in registers from one sphere to the next.
    #[inline(always)]
    fn advance(
        &self,
        (x, v, w): (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia, blocked, clump): (f64, f64, u8, u32),
        (f, t): (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        if clump != FREE {
            // Clump members move with their clump (see integrate_clumps).
            return (0.0, [0.0; 4]);
        }
        if blocked != 0 {
            return self.advance_blocked((x, v, w), (m, inertia, blocked), (f, t), x0);
        }
        self.advance_free((x, v, w), (m, inertia), (f, t), x0)
    }

    /// [`Motion::advance`] of a sphere with every degree of freedom free, outside any clump.
    #[inline(always)]
    fn advance_free(
        &self,
        (x, v, w): (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia): (f64, f64),
        (f, t): (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        let (damping, dt) = (self.damping, self.dt);
        // The three components side by side in lanes: one vector instruction where the
        // component-wise form took three.
        let (x4, v4, w4) = (widen(*x), widen(*v), widen(*w));
        let (lx, reference) = match &self.affine_columns {
            Some((l, f, _)) => (mat_vec4(l, x4), mat_vec4(f, widen(*x0))),
            None => ([0.0; 4], widen(*x0)),
        };
        // One packed division instead of six scalar ones: the divider is the slowest unit here.
        let (inv_m, inv_i) = simd::reciprocals(m, inertia);
        let acc = add4(scale4(f, inv_m), self.gravity_lanes);
        let v4 = add4(v4, scale4(cundall4(acc, v4, damping, dt), dt));
        let moving = add4(v4, lx);
        let x4 = add4(x4, scale4(moving, dt));
        // Newton's law holds for the whole velocity `v + L x`, which only forces change (YADE's
        // default `homoDeform`): a sphere that moved by `moving dt` keeps its fluctuation around
        // the field at its new place, `L moving dt` less. (Kept at the old place's field, a sphere
        // rising across a shear flow would gain speed along it without a force.)
        let v4 = match &self.affine_columns {
            Some((_, _, l_dt)) => sub4(v4, mat_vec4(l_dt, moving)),
            None => v4,
        };
        let w4 = add4(w4, scale4(cundall4(scale4(t, inv_i), w4, damping, dt), dt));
        (*x, *v, *w) = (narrow(x4), narrow(v4), narrow(w4));
        let d2 = mul4(sub4(x4, reference), sub4(x4, reference));
        (d2[0] + d2[1] + d2[2], add4(d2, add4(v4, w4)))
    }

    /// [`Motion::advance`] of a sphere with blocked degrees of freedom, component by component.
    fn advance_blocked(
        &self,
        (x, v, w): (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia, blocked): (f64, f64, u8),
        (f, t): (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        let Motion { gravity, damping, dt, affine, .. } = self;
        let (damping, dt) = (*damping, *dt);
        let (lx, reference) = match affine {
            Some((l, f)) => (mat_vec(l, *x), mat_vec(f, *x0)),
            None => ([0.0; 3], *x0),
        };
        let damp = |acc: f64, vel: f64| cundall(acc, vel, damping, dt);
        let (inv_m, inv_i) = simd::reciprocals(m, inertia);
        for a in 0..3 {
            if blocked & (dof::X << a) == 0 {
                v[a] += damp(f[a] * inv_m + gravity[a], v[a]) * dt;
            }
            if blocked & (dof::RX << a) == 0 {
                w[a] += damp(t[a] * inv_i, w[a]) * dt;
            }
        }
        let moving = add(*v, lx);
        for a in 0..3 {
            x[a] += moving[a] * dt;
        }
        if let Some((l, _)) = affine {
            // Newton's law for the whole velocity, as in `advance_free`; a blocked component keeps
            // its prescribed fluctuation.
            let field_change = mat_vec(l, moving);
            for a in 0..3 {
                if blocked & (dof::X << a) == 0 {
                    v[a] -= field_change[a] * dt;
                }
            }
        }
        let d = sub(*x, reference);
        let d2 = [d[0] * d[0], d[1] * d[1], d[2] * d[2]];
        (d2[0] + d2[1] + d2[2], add4(widen(d2), add4(widen(*v), widen(*w))))
    }
}

/// YADE's Cundall damping of an acceleration: reduced by `damping` against the sign of the
/// power at mid-step (`damping` >= 0, so copysign is damping times that sign).
#[inline(always)]
fn cundall(acc: f64, vel: f64, damping: f64, dt: f64) -> f64 {
    acc * (1.0 - damping.copysign(acc * (vel + 0.5 * dt * acc)))
}

/// [`cundall`] on each lane.
#[inline(always)]
fn cundall4(acc: Lanes, vel: Lanes, damping: f64, dt: f64) -> Lanes {
    // Spelled out: `array::map` is not inlined for certain, and this must be.
    [
        cundall(acc[0], vel[0], damping, dt),
        cundall(acc[1], vel[1], damping, dt),
        cundall(acc[2], vel[2], damping, dt),
        cundall(acc[3], vel[3], damping, dt),
    ]
}

/// How far the spheres of a run went since the candidate lists were built, and whether all
/// their states stayed finite.
#[derive(Clone, Copy, Default)]
struct Travel {
    worst2: f64,
    /// Sums of every displacement and velocity, lane by lane: finite only if every term is (no
    /// finite state is large enough to overflow them), so one test at the end replaces one per
    /// sphere.
    check: Lanes,
}

impl Travel {
    /// A sphere that moved `moved2` squared; `state` holds its squared displacements plus its
    /// velocities (only finiteness matters).
    #[inline(always)]
    fn record(&mut self, moved2: f64, state: Lanes) {
        // Not f64::max: its NaN handling lengthens the chain from one sphere to the next, and a
        // NaN shows in `check` anyway.
        if moved2 > self.worst2 {
            self.worst2 = moved2;
        }
        self.check = add4(self.check, state);
    }

    /// The largest displacement, NaN if some state stopped being finite.
    fn largest(self) -> f64 {
        if self.check.iter().all(|c| c.is_finite()) {
            self.worst2.sqrt()
        } else {
            f64::NAN
        }
    }
}

/// Rigid-body integration of the clumps (forces and torques gathered from their members), then
/// members placed and given the clump's velocity field. Returns the largest member displacement
/// since the candidate lists were built (affine part excluded).
fn integrate_clumps(
    cl: &mut Clumps,
    sp: &mut Spheres,
    x_at_build: &[Vec3],
    gravity: Vec3,
    damping: f64,
    dt: f64,
    affine: Option<(Matrix3<f64>, Matrix3<f64>)>,
) -> f64 {
    use nalgebra::{UnitQuaternion, Vector3};
    let damp = |acc: f64, vel: f64| cundall(acc, vel, damping, dt);
    let mut moved: f64 = 0.0;
    for c in 0..cl.len() {
        let xc = cl.x[c];
        let (mut f, mut t) = ([0.0; 3], [0.0; 3]);
        for m in cl.members_of(c) {
            let i = cl.members[m] as usize;
            f = add(f, sp.force[i]);
            t = add(add(t, sp.torque[i]), cross(sub(sp.x[i], xc), sp.force[i]));
        }
        cl.force[c] = f;
        cl.torque[c] = t;
        let mass = cl.mass[c];
        let lx = match &affine {
            Some((l, _)) => mat_vec(l, xc),
            None => [0.0; 3],
        };
        for a in 0..3 {
            let acc = damp(f[a] / mass + gravity[a], cl.v[c][a]);
            cl.v[c][a] += acc * dt;
        }
        let moving = add(cl.v[c], lx);
        for a in 0..3 {
            cl.x[c][a] += moving[a] * dt;
        }
        if let Some((l, _)) = &affine {
            // Newton's law for the whole velocity, as for a sphere (`Motion::advance_free`).
            let field_change = mat_vec(l, moving);
            for a in 0..3 {
                cl.v[c][a] -= field_change[a] * dt;
            }
        }
        // Euler's equations in the world frame: I w' = T - w x (I w).
        let rot = cl.q[c].to_rotation_matrix();
        let i_body = Matrix3::from_diagonal(&Vector3::new(cl.inertia[c][0], cl.inertia[c][1], cl.inertia[c][2]));
        let i_world = rot.matrix() * i_body * rot.matrix().transpose();
        let w = Vector3::new(cl.w[c][0], cl.w[c][1], cl.w[c][2]);
        let rhs = Vector3::new(t[0], t[1], t[2]) - w.cross(&(i_world * w));
        let alpha = i_world.try_inverse().map(|inv| inv * rhs).unwrap_or_else(Vector3::zeros);
        for a in 0..3 {
            cl.w[c][a] += damp(alpha[a], cl.w[c][a]) * dt;
        }
        let wn = Vector3::new(cl.w[c][0], cl.w[c][1], cl.w[c][2]);
        cl.q[c] = UnitQuaternion::from_scaled_axis(wn * dt) * cl.q[c];
        let xc = cl.x[c];
        for m in cl.members_of(c) {
            let i = cl.members[m] as usize;
            let l = cl.local[m];
            let arm = cl.q[c] * Vector3::new(l[0], l[1], l[2]);
            let arm = [arm[0], arm[1], arm[2]];
            sp.x[i] = add(xc, arm);
            // A member's fluctuation: the clump's rigid motion less the field's change across the arm.
            let field_across_arm = match &affine {
                Some((l, _)) => mat_vec(l, arm),
                None => [0.0; 3],
            };
            sp.v[i] = sub(add(cl.v[c], cross(cl.w[c], arm)), field_across_arm);
            sp.w[i] = cl.w[c];
            let reference = match &affine {
                Some((_, fm)) => mat_vec(fm, x_at_build[i]),
                None => x_at_build[i],
            };
            let d = sub(sp.x[i], reference);
            let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if !dist.is_finite() {
                return f64::NAN;
            }
            moved = moved.max(dist);
        }
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The work (spheres and their pairs) of each piece of `bounds`, and what it should be when
    /// the workers get `shares` of `total`, split equally between the pieces each owns.
    fn work_and_targets(bounds: &PieceBounds, work_before: impl Fn(usize) -> usize, shares: &[f64]) -> Vec<(f64, f64)> {
        let pieces = bounds.spheres.len() - 1;
        let total = work_before(*bounds.spheres.last().unwrap()) as f64;
        let starts = crate::par::piece_starts(&crate::par::owners(pieces), shares);
        (0..pieces)
            .map(|p| {
                let work = (work_before(bounds.spheres[p + 1]) - work_before(bounds.spheres[p])) as f64;
                (work, total * (starts[p + 1] - starts[p]))
            })
            .collect()
    }

    #[test]
    fn workers_get_equal_work_when_the_last_spheres_hold_most_pairs() {
        // 2000 spheres: sphere i is the first of i / 500 pairs (the last quarter holds 3 a
        // sphere, the first none), as the wrap-round pairs of a periodic cell load its last slab.
        let (spheres, mut pairs) = (2000, PairList::default());
        let pairs_of = |i: usize| i / 500;
        for i in 0..spheres {
            for k in 0..pairs_of(i) {
                pairs.a.push(i as u32);
                pairs.b.push(k as u32);
            }
        }
        let walls = PairList::default();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let mut bounds = PieceBounds::default();
        pool.install(|| bounds.refresh(spheres, 0, &pairs, &walls));
        let pieces = bounds.spheres.len() - 1;
        assert!(pieces > 2, "{pieces} pieces");
        let work_before = |s: usize| s + pairs.a.partition_point(|&a| (a as usize) < s);
        // Before any piece has been timed, each of the two workers gets half the work, split
        // equally between its pieces. A cut can only fall between spheres: a piece may be off by
        // one sphere's work (itself and its pairs).
        let one_sphere = (1 + pairs_of(spheres - 1)) as f64;
        for (p, (work, target)) in work_and_targets(&bounds, work_before, &[0.5, 0.5]).into_iter().enumerate() {
            assert!((work - target).abs() <= one_sphere, "piece {p}: {work} units of work, its share {target}");
        }
        let cut_pairs: Vec<usize> = bounds.spheres[1..pieces].iter().map(|&s| work_before(s) - s).collect();
        assert_eq!(bounds.sphere_pairs, cut_pairs, "pair lists cut where their first spheres are");
        assert!(bounds.spheres[1] - bounds.spheres[0] > bounds.spheres[pieces] - bounds.spheres[pieces - 1]);
    }

    #[test]
    fn cuts_give_a_slower_worker_less_work() {
        // A chain of 1600 spheres: 4 pieces, two a worker.
        let (spheres, mut pairs) = (1600, PairList::default());
        for i in 1..spheres {
            pairs.a.push(i as u32);
            pairs.b.push(i as u32 - 1);
        }
        let walls = PairList::default();
        let work_before = |s: usize| s + pairs.a.partition_point(|&a| (a as usize) < s);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let mut bounds = PieceBounds::default();
        pool.install(|| bounds.refresh(spheres, 0, &pairs, &walls));
        assert_eq!(bounds.spheres.len() - 1, 4);
        // Worker 1 takes twice as long per unit of work as worker 0, step after step.
        for _ in 0..RECUT_AFTER_STEPS {
            let timed: Vec<[(usize, f64); 2]> = (0..4)
                .map(|p| {
                    let w = crate::par::owners(4)[p];
                    let seconds_per_unit = if w == 0 { 1e-9 } else { 2e-9 };
                    let spheres = (bounds.spheres[p + 1] - bounds.spheres[p]) as f64;
                    let contacts = bounds.units[p] as f64 - spheres;
                    [(w, contacts * seconds_per_unit), (w, spheres * seconds_per_unit)]
                })
                .collect();
            pool.install(|| bounds.learn(&timed));
            pool.install(|| bounds.refresh(spheres, 0, &pairs, &walls));
        }
        // Then the cuts give worker 0 two thirds of the work: both finish together.
        let one_sphere = 2.0;
        for (p, (work, target)) in
            work_and_targets(&bounds, work_before, &[2.0 / 3.0, 1.0 / 3.0]).into_iter().enumerate()
        {
            assert!((work - target).abs() <= one_sphere, "piece {p}: {work} units of work, its share {target}");
        }
    }

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
                let m = sim.add_material("grains", 2650.0).unwrap();
                sim.set_contact_law(Box::new(SpringAndDrag(Default::default())), None).unwrap();
                let (r, side) = (1e-3, 12);
                let spacing = 1.9 * r;
                let width = side as f64 * spacing;
                sim.set_cell(Some(PeriodicCell::new_box([width; 3])));
                let hi = [width - 0.5 * spacing + r; 3];
                let placed =
                    crate::dem::generate::lattice([0.5 * spacing - r; 3], hi, spacing, 0.93 * r, 0.01 * r, 3).unwrap();
                for (x, radius) in placed {
                    sim.add_sphere(m, x, radius, [0.0; 3]).unwrap();
                }
                sim.set_dt(0.2 * sim.critical_dt().unwrap()).unwrap();
                let l = &mut sim.cell.as_mut().unwrap().velocity_gradient;
                for a in 0..3 {
                    l[(a, a)] = -0.05 / (200.0 * sim.dt);
                }
                l[(0, 2)] = 0.1 / (200.0 * sim.dt);
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
                (sim.spheres.x, sim.spheres.w, sim.pairs.touching_count(), cuts.len(), shares_cut_for)
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
            let sand = sim.add_material("sand", 2650.0).unwrap();
            let glass = sim.add_material("glass", 2500.0).unwrap();
            sim.set_contact_law(Box::new(SpringAndDrag(Default::default())), Some((sand, sand))).unwrap();
            sim.add_sphere(sand, [0.0, 0.0, 0.006], 0.005, [0.0; 3]).unwrap();
            if near_wall {
                sim.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], glass));
            } else {
                sim.add_sphere(glass, [0.0, 0.0, -0.005], 0.005, [0.0; 3]).unwrap();
            }
            sim.skin = 0.002;
            let Err(GraniteError::Setup(message)) = sim.rebuild_candidates() else {
                panic!("near a wall: {near_wall}: a pair without a law must be refused");
            };
            assert!(message.contains("\"sand\"") && message.contains("\"glass\""), "{message}");
        }
    }

    #[test]
    fn each_piece_knows_the_first_piece_whose_spheres_its_contacts_read() {
        // A chain (sphere i paired with i - 1) closed round a periodic cell: the last sphere's
        // pair with sphere 0 wraps round, as in a periodic cell.
        let (spheres, mut pairs) = (4000, PairList::default());
        for i in 1..spheres {
            if i == spheres - 1 {
                pairs.a.push(i as u32);
                pairs.b.push(0);
            }
            pairs.a.push(i as u32);
            pairs.b.push(i as u32 - 1);
        }
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let mut bounds = PieceBounds::default();
        pool.install(|| bounds.refresh(spheres, 0, &pairs, &PairList::default()));
        let pieces = bounds.spheres.len() - 1;
        assert!(pieces > 3, "{pieces} pieces");
        let mut expected: Vec<usize> = (0..pieces).map(|q| q.saturating_sub(1)).collect();
        expected[pieces - 1] = 0;
        assert_eq!(bounds.reads_from, expected);
    }

    #[test]
    fn first_build_numbers_spheres_slab_by_slab_along_the_longest_side() {
        let mut sim = DemSim::new();
        let m = sim.add_material("grains", 1000.0).unwrap();
        let (r, spacing) = (0.01, 0.05);
        // 8 x 40 x 4 spheres far apart (no contacts), added from the far end of y backwards.
        let mut placed = Vec::new();
        for j in (0..40).rev() {
            for i in 0..8 {
                for k in 0..4 {
                    placed.push([i as f64 * spacing, j as f64 * spacing, k as f64 * spacing]);
                }
            }
        }
        for x in &placed {
            sim.add_sphere(m, *x, r, [0.0; 3]).unwrap();
        }
        let before: std::collections::HashMap<u64, Vec3> =
            sim.spheres.id.iter().copied().zip(sim.spheres.x.iter().copied()).collect();
        sim.set_dt(1e-6).unwrap();
        sim.step().unwrap();
        assert_eq!(sim.spheres.len(), placed.len());
        for (id, x) in sim.spheres.id.iter().zip(&sim.spheres.x) {
            assert_eq!(before[id], *x, "sphere {id} lost its position");
        }
        let y = &sim.spheres.x;
        assert!(y.windows(2).all(|w| w[0][1] <= w[1][1]), "not ordered along y, the longest side");
        assert!(y[0][1] == 0.0 && y[y.len() - 1][1] == 39.0 * spacing);
    }
}
