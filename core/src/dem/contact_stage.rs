//! The contact stage: for each candidate pair, its geometry (`sphere_sphere`, sphere–wall),
//! then its contact law on chunks of touching pairs, then the forces written back to the pairs and
//! summed into the spheres' loads in one order on any thread count (see `write_back`).

use crate::dem::cell::PeriodicCell;
use crate::dem::contacts::PairList;
use crate::dem::rows::SharedRows;
use crate::dem::walls::Wall;
use crate::ext::{ContactBatch, ContactLaw};
use crate::math::{add3 as add, cross3 as cross, dot3, mat_vec, sub3 as sub, Vec3};
use std::ops::Range;
use std::sync::Arc;

/// What the spheres' contact stage reads besides the spheres and their pairs.
pub(crate) struct SphereSurroundings<'a> {
    pub walls: &'a [Wall],
    pub laws: &'a [Arc<dyn ContactLaw>],
    pub dt: f64,
    pub cell: Option<&'a PeriodicCell>,
}

/// The spheres' contact stage on one thread (`ContactsAndMotion` in step.rs is the parallel step,
/// fused with the motion). Reads the spheres' positions, velocities and radii and the
/// surroundings; writes the pairs' contacts, forces and history, and the spheres' forces and
/// torques (sphere–sphere and sphere–wall), summed in pair order.
pub(crate) struct SphereContacts;

impl SphereContacts {
    pub(crate) fn run(
        spheres: &mut crate::dem::particles::Spheres,
        (pairs, wall_pairs): (&mut PairList, &mut PairList),
        around: &SphereSurroundings<'_>,
    ) {
        let strides = (pairs.param_stride, pairs.history_stride);
        let crate::dem::particles::Spheres { x, v, w, radius, force, torque, .. } = spheres;
        let rotation = around.laws.iter().any(|l| l.resists_rotation());
        let sp = Motions { first: 0, x, v, w, radius, cell: around.cell, rotation };
        let mut scratch = ScratchGuard::take();
        let mut none = Handover::default();
        contact_job_wide(ContactJob {
            sp: &sp,
            walls: around.walls,
            sphere_pairs: PairChunk::whole(pairs, strides),
            wall_pairs: PairChunk::whole(wall_pairs, strides),
            laws: around.laws,
            dt: around.dt,
            scratch: &mut scratch,
            loads: Loads { first: 0, force, torque, handover: &mut none, starts: &[] },
        });
        debug_assert!(none.0.is_empty(), "one piece holds every pair");
    }
}

/// Pairs per law call.
const CHUNK: usize = 128;

thread_local! {
    /// Scratch buffers are large (about 20 kB): keep one per thread across steps instead of
    /// allocating and zeroing one per step (that dominated small RVEs).
    static SCRATCH: std::cell::RefCell<Vec<Box<Scratch>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A scratch buffer borrowed from the thread's pool, returned on drop.
pub(super) struct ScratchGuard(Option<Box<Scratch>>);

impl ScratchGuard {
    pub(super) fn take() -> ScratchGuard {
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
pub(super) struct Scratch {
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
pub(super) struct Motions<'a> {
    /// The sphere in the first row of these arrays (sphere `i` is row `i - first`).
    pub(super) first: usize,
    pub(super) x: &'a [Vec3],
    pub(super) v: &'a [Vec3],
    pub(super) w: &'a [Vec3],
    pub(super) radius: &'a [f64],
    /// The periodic cell: images and the affine velocity field across it.
    pub(super) cell: Option<&'a PeriodicCell>,
    /// Whether some contact law resists relative rotation (else spins and moments are skipped).
    pub(super) rotation: bool,
}

/// The loads (force and torque sums) of a run of consecutive spheres from sphere `first`, which
/// the contact stage adds its forces to: all spheres when stepping sequentially, a parallel
/// piece's otherwise.
pub(super) struct Loads<'a> {
    pub(super) first: usize,
    pub(super) force: &'a mut [Vec3],
    pub(super) torque: &'a mut [Vec3],
    /// The loads of pairs whose second sphere lies before `first`, for the gather.
    pub(super) handover: &'a mut Handover,
    /// The first sphere of each parallel piece, then the sphere count: where to hand loads over.
    pub(super) starts: &'a [usize],
}

/// A load handed over: the second sphere of a pair, the force on its first sphere and the torque
/// on the second.
type HandedLoad = (u32, Vec3, Vec3);

/// The loads of one parallel piece's touching pairs whose second sphere lies in an earlier piece:
/// the last terms of those spheres' sums (see `write_back`), which the contact stage hands over
/// to the gather. One list per earlier piece, each in pair order (so each sphere's loads are),
/// which that piece's gather reads whole. Filled anew every step.
#[derive(Debug, Default)]
pub(crate) struct Handover(pub(super) Vec<Vec<HandedLoad>>);

impl Handover {
    /// Empties the lists for the `earlier` pieces before this one, keeping their storage.
    pub(super) fn start(&mut self, earlier: usize) {
        self.0.resize_with(earlier, Vec::new);
        self.0.iter_mut().for_each(Vec::clear);
    }

    #[inline(always)]
    fn push(&mut self, piece: usize, sphere: usize, force: Vec3, torque: Vec3) {
        self.0[piece].push((sphere as u32, force, torque));
    }

    /// The loads handed over to the spheres of `piece`, in pair order.
    pub(super) fn to(&self, piece: usize) -> &[HandedLoad] {
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
    pub(super) fn fit(&mut self, pieces: usize) -> &mut [Handover] {
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
pub(super) struct PairChunk<'a> {
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
    pub(super) fn whole(p: &'a mut PairList, strides: (usize, usize)) -> PairChunk<'a> {
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
pub(super) fn piece_range(cuts: &[usize], total: usize, q: usize) -> Range<usize> {
    let start = if q == 0 { 0 } else { cuts[q - 1] };
    start..cuts.get(q).copied().unwrap_or(total)
}

/// A pair list lent to a parallel pass: what the pass only reads, shared; what it writes (the
/// history, the contact flags and the forces), as rows that each piece borrows for its own pairs.
pub(super) struct SharedPairs<'a> {
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
    pub(super) fn new(list: &'a mut PairList, strides: (usize, usize)) -> SharedPairs<'a> {
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

    pub(super) fn len(&self) -> usize {
        self.a.len()
    }

    /// The pairs `range`, their history, flags and forces to change; panics when out of range.
    ///
    /// # Safety
    /// While the chunk is used, no other chunk of an overlapping range may be.
    pub(super) unsafe fn chunk(&self, range: Range<usize>) -> PairChunk<'a> {
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
pub(super) struct Run {
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
pub(super) struct ContactJob<'j> {
    pub(super) sp: &'j Motions<'j>,
    pub(super) walls: &'j [Wall],
    pub(super) sphere_pairs: PairChunk<'j>,
    pub(super) wall_pairs: PairChunk<'j>,
    pub(super) laws: &'j [Arc<dyn ContactLaw>],
    pub(super) dt: f64,
    pub(super) scratch: &'j mut Scratch,
    /// The loads of the run's spheres (those the pairs start from), summed anew.
    pub(super) loads: Loads<'j>,
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

crate::wide_kernel!(pub(super) fn contact_job_wide(job: ContactJob<'_>) => contact_job);

/// Sphere-sphere geometry (`sphere_sphere`) and contact forces; in a periodic cell the second
/// sphere may be an image, whose velocity includes the affine field across the cell.
#[inline(always)]
pub(super) fn sphere_contacts(
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
pub(super) fn wall_contacts(
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
            s.rel_velocity[e] = sub(wall.point_velocity(geo.point), va);
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
