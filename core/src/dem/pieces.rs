//! Where the parallel stages cut the spheres and the pair lists, and how the cuts follow the
//! workers' measured speeds.

use crate::dem::contacts::PairList;
use crate::dem::sim::DemSim;

/// Fewest spheres worth a parallel piece of their own (with their pairs). Every piece boundary
/// hands loads over (see `write_back`), which costs instructions: the 1500-sphere periodic RVE,
/// stepped in the pieces of two workers on one thread, took 11 % more instructions than the
/// sequential pass in 11 pieces of 128 spheres or more, and 6.6 % in 4 of 375 (callgrind).
const MIN_SPHERES_PER_PIECE: usize = 375;

/// Where the parallel stages cut the spheres and the pair lists: into pieces of consecutive
/// spheres with the pairs whose first spheres fall in them (pairs are sorted by first sphere), so
/// a worker mostly sums forces it computed itself, from its own cache. Found again when the lists
/// are rebuilt, the piece count changes, or the workers' speeds drift apart; any cuts give the
/// same forces.
#[derive(Debug, Clone, Default)]
pub(crate) struct PieceBounds {
    /// Sphere count, piece count, rebuild count and list lengths the cuts were found for.
    pub(super) key: (usize, usize, u64, usize, usize),
    /// The first sphere of each piece, then the sphere count.
    pub(super) spheres: Vec<usize>,
    /// Where each piece after the first starts in the pair lists.
    pub(super) sphere_pairs: Vec<usize>,
    pub(super) wall_pairs: Vec<usize>,
    /// For each piece, the first piece holding a sphere it reads (the second spheres of its pairs
    /// lie before their first): its contacts read the spheres of pieces `reads_from[q]..=q`.
    pub(super) reads_from: Vec<usize>,
    /// Units of work of each piece (see [`PieceBounds::refresh`]).
    pub(super) units: Vec<usize>,
    /// Each worker's share of the work the cuts were made for.
    pub(super) shares: Vec<f64>,
    /// What the steps since taught of the workers' speeds, and how many steps ago the cuts were
    /// made.
    pub(super) speeds: crate::par::WorkerSpeeds,
    pub(super) age: u64,
}

/// A worker's share of the work that has to drift this far from the one the pieces were cut for
/// before they are cut again, and the steps that have to pass: recutting costs a pass over the
/// pair list (a few microseconds in a 1500-sphere RVE), and the speeds' estimates are noisy.
const RECUT_DRIFT: f64 = 0.01;
pub(super) const RECUT_AFTER_STEPS: u64 = 10;
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
    pub(super) fn refresh(&mut self, spheres: usize, rebuilds: u64, pairs: &PairList, walls: &PairList) {
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
    pub(super) fn learn(&mut self, timed: &[[(usize, f64); 2]]) {
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

/// Fewest spheres stepped in parallel (enough for several pieces): below, pieces are not
/// regions of space (see `order_spheres_in_space`), and two threads were slower than one
/// (periodic RVEs, best of 7: 1000 spheres 110 against 98 us a step; 1500: 121 against 148).
const MIN_SPHERES_IN_PARALLEL: usize = crate::dem::rebuild::MIN_SPHERES_TO_ORDER;

/// Whether `spheres` are enough to share between the threads of the pool this runs in (none
/// when it runs on one thread).
pub(crate) fn worth_parallel(spheres: usize) -> bool {
    spheres >= MIN_SPHERES_IN_PARALLEL && rayon::current_num_threads() > 1
}

impl DemSim {
    /// Whether this step runs its stages in parallel pieces of consecutive spheres (and their
    /// pairs), rather than on the calling thread (an RVE, one thread, or too few spheres). Both
    /// make the same sums in the same order (see `write_back`).
    pub(crate) fn in_parallel(&self) -> bool {
        !self.sequential && worth_parallel(self.world.spheres.len())
    }
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
}
