//! The device buffers' layout (`rve.wgsl`), filled from the host's RVEs and read back into them.

use granite_core::dem::contacts::PairList;
use granite_core::dem::sim::VerletState;
use granite_core::dem::DemSim;
use granite_core::ext::{DeviceLaw, RveReport};
use granite_core::{GraniteError, Result};
use nalgebra::Matrix3;

pub const RVE_STRIDE: usize = 64;
/// Per sphere: x, v, w, x at the last rebuild, radius, mass, inertia.
const SPH_STRIDE: usize = 16;
/// Per pair slot: history (7), touching, force on the first sphere, torques on both.
const PF_STRIDE: usize = 17;
const PF_TOUCH: usize = 7;
const PF_FORCE: usize = 8;
const PF_TA: usize = 11;
const PF_TB: usize = 14;
/// What a rebuild carries over of a kept pair's slot: history (7) and touching.
const PF_KEPT: usize = 8;
/// Fewest slots per sphere in the device's pair rows.
const MIN_SLOTS: usize = 16;

/// Indices into the batch's constants (`consts`).
#[derive(Clone, Copy)]
enum Const {
    /// Slots per sphere.
    Slots,
    /// Offsets into `ints`: the pair rows (4 per slot: second sphere, shift), the rows being
    /// rebuilt, the incoming slots (1 per slot), the incoming pairs while rebuilding (4 per
    /// slot), per sphere its counts (rows, incoming, wrap offset, row start, cell: 8 per
    /// sphere), the sphere ids sorted by cell during a rebuild (1 per sphere).
    Rows,
    RebuiltRows,
    Incoming,
    IncomingRebuilt,
    Counts,
    Items,
    Skin,
    Damping,
    /// Most steps one dispatch takes (the host dispatches again).
    Chunk,
    /// Most candidate-list rebuilds one dispatch makes (0: no limit).
    Rebuilds,
    /// 1: the lists are rebuilt before every step (benchmarks).
    ForceRebuild,
    /// The contact law's constants (`DeviceLaw::constants`) from here on.
    LawFirst,
}
const CONSTS: usize = Const::LawFirst as usize + DeviceLaw::MOST_CONSTANTS;

/// How the kernel's work goes in dispatches (see `Gpu::chunk`).
#[derive(Debug, Clone, Copy)]
pub struct Dispatching {
    /// Most steps one dispatch takes.
    pub chunk: u32,
    /// Most candidate-list rebuilds one dispatch makes (0: no limit).
    pub rebuilds: u32,
    /// Rebuild the lists before every step, needed or not (benchmarks).
    pub force_rebuild: bool,
}

/// Offsets into an RVE's record.
#[derive(Clone, Copy)]
pub enum Rec {
    /// The cell matrix, row-major.
    H = 0,
    /// The cell matrix at the last rebuild.
    HBuild = 9,
    /// The velocity gradient of this call.
    L = 18,
    Dt = 27,
    /// Full steps of this call.
    Steps = 28,
    /// A shorter last step, or 0.
    LastDt = 29,
    /// First sphere and spheres.
    First = 30,
    Count = 31,
    /// The lists must be rebuilt before the next step.
    Rebuild = 32,
    RMax = 33,
    RMin = 34,
    /// 0, or a `Failure` code.
    Error = 35,
    ErrorValue = 36,
    Time = 37,
    Step = 38,
    Rebuilds = 39,
    Flips = 40,
    /// Love-Weber stress, Voigt, tension positive.
    Stress = 41,
    Contacts = 47,
    Ends = 48,
    Rattlers = 49,
    Floaters = 50,
    /// Steps taken by this call (its dispatches so far).
    Taken = 51,
    /// In record w: the RVE workgroup w steps (the longest orders first).
    Queue = 52,
    /// Distance tests of the candidate searches (all rebuilds so far).
    Tests = 53,
}

/// The constants the kernel is written against, as WGSL (put before `rve.wgsl`).
pub fn wgsl_constants() -> String {
    use Const as C;
    let u = [
        ("C_K", C::Slots as usize),
        ("C_PI", C::Rows as usize),
        ("C_PJ", C::RebuiltRows as usize),
        ("C_INC", C::Incoming as usize),
        ("C_INCT", C::IncomingRebuilt as usize),
        ("C_CNT", C::Counts as usize),
        ("C_ITEMS", C::Items as usize),
        ("C_SKIN", C::Skin as usize),
        ("C_DAMPING", C::Damping as usize),
        ("C_CHUNK", C::Chunk as usize),
        ("C_REBUILDS", C::Rebuilds as usize),
        ("C_FORCE_REBUILD", C::ForceRebuild as usize),
        ("C_LAW_FIRST", C::LawFirst as usize),
        ("N_CONSTS", CONSTS),
        ("RVE_STRIDE", RVE_STRIDE),
        ("R_H", Rec::H as usize),
        ("R_HB", Rec::HBuild as usize),
        ("R_L", Rec::L as usize),
        ("R_DT", Rec::Dt as usize),
        ("R_STEPS", Rec::Steps as usize),
        ("R_LAST_DT", Rec::LastDt as usize),
        ("R_FIRST", Rec::First as usize),
        ("R_COUNT", Rec::Count as usize),
        ("R_REBUILD", Rec::Rebuild as usize),
        ("R_RMAX", Rec::RMax as usize),
        ("R_RMIN", Rec::RMin as usize),
        ("R_ERROR", Rec::Error as usize),
        ("R_ERROR_VALUE", Rec::ErrorValue as usize),
        ("R_TIME", Rec::Time as usize),
        ("R_STEP", Rec::Step as usize),
        ("R_REBUILDS", Rec::Rebuilds as usize),
        ("R_FLIPS", Rec::Flips as usize),
        ("R_STRESS", Rec::Stress as usize),
        ("R_CONTACTS", Rec::Contacts as usize),
        ("R_ENDS", Rec::Ends as usize),
        ("R_RATTLERS", Rec::Rattlers as usize),
        ("R_FLOATERS", Rec::Floaters as usize),
        ("R_TAKEN", Rec::Taken as usize),
        ("R_QUEUE", Rec::Queue as usize),
        ("R_TESTS", Rec::Tests as usize),
        ("SPH_STRIDE", SPH_STRIDE),
        ("PF_STRIDE", PF_STRIDE),
        ("PF_TOUCH", PF_TOUCH),
        ("PF_FORCE", PF_FORCE),
        ("PF_TA", PF_TA),
        ("PF_TB", PF_TB),
        ("PF_KEPT", PF_KEPT),
    ];
    let mut out: String = u.iter().map(|(name, v)| format!("const {name}: u32 = {v}u;\n")).collect();
    for (name, f) in [
        ("FAIL_TOO_FAST", Failure::TooFast),
        ("FAIL_NOT_FINITE", Failure::NotFinite),
        ("FAIL_TOO_MANY_PAIRS", Failure::TooManyPairs),
        ("FAIL_CELL_COLLAPSED", Failure::CellCollapsed),
        ("FAIL_LOST_PAIR", Failure::LostPair),
    ] {
        out += &format!("const {name}: f64 = {}.0lf;\n", f as u32);
    }
    out
}

/// Why an RVE stopped on the device (the kernel's FAIL_ codes).
#[derive(Debug, Clone, Copy)]
pub enum Failure {
    TooFast = 1,
    NotFinite = 2,
    TooManyPairs = 3,
    CellCollapsed = 4,
    LostPair = 5,
}

impl Failure {
    fn from_code(code: f64) -> Option<Failure> {
        [Failure::TooFast, Failure::NotFinite, Failure::TooManyPairs, Failure::CellCollapsed, Failure::LostPair]
            .into_iter()
            .find(|&f| f as u32 as f64 == code)
    }
}

/// The contact law the kernel runs, with its constants (one per batch).
#[derive(Debug, Clone, PartialEq)]
pub struct LawConstants {
    pub law: DeviceLaw,
    skin: f64,
    damping: f64,
}

impl LawConstants {
    /// The constants of an RVE's law, or why the device cannot step this RVE.
    pub fn of(sim: &DemSim) -> Result<LawConstants> {
        let refuse = |what: &str| {
            Err(GraniteError::Setup(format!("device \"gpu\": the RVE {what}; run it with device \"cpu\"")))
        };
        if sim.world.cell.is_none() {
            return refuse("has no periodic cell");
        }
        if !sim.world.walls.is_empty() || !sim.world.clumps.is_empty() || !sim.world.kinds.is_empty() {
            return refuse("holds walls, clumps or bodies of plugin kinds (the device steps spheres only)");
        }
        if sim.world.spheres.blocked.iter().any(|&b| b != 0) || !sim.world.external.is_empty() || sim.energy.is_some() {
            return refuse("has blocked spheres, external loads or an energy tracker");
        }
        if sim.world.gravity != [0.0; 3] || sim.world.cell_control.is_some() {
            return refuse("has gravity or a cell servo");
        }
        let [law] = &sim.world.laws[..] else { return refuse("has several contact laws (the device runs one)") };
        let form = match law.device_form() {
            Ok(form) => form,
            Err(why) => return refuse(&format!("uses contact law \"{}\", which {why}", law.name())),
        };
        if form.constants.len() > DeviceLaw::MOST_CONSTANTS {
            return refuse(&format!(
                "uses contact law \"{}\", whose device form has {} constants (at most {})",
                law.name(),
                form.constants.len(),
                DeviceLaw::MOST_CONSTANTS
            ));
        }
        Ok(LawConstants { law: form, skin: sim.skin, damping: sim.world.damping })
    }
}

/// Where each region of `ints` starts (see `Const::Rows`), and its length.
struct IntRegions {
    rows: usize,
    rebuilt_rows: usize,
    incoming: usize,
    incoming_rebuilt: usize,
    counts: usize,
    items: usize,
    len: usize,
}

impl IntRegions {
    fn of(spheres: usize, slots: usize) -> IntRegions {
        let slot_count = spheres * slots;
        let rows = 0;
        let rebuilt_rows = rows + 4 * slot_count;
        let incoming = rebuilt_rows + 4 * slot_count;
        let incoming_rebuilt = incoming + slot_count;
        let counts = incoming_rebuilt + 4 * slot_count;
        let items = counts + 8 * spheres;
        IntRegions { rows, rebuilt_rows, incoming, incoming_rebuilt, counts, items, len: items + spheres }
    }
}

/// Where each RVE's spheres and pair slots lie in the buffers.
pub struct Layout {
    /// First sphere of each RVE, and one past the last.
    first: Vec<usize>,
    /// Slots per sphere (the longest pair row or incoming list, with room to grow).
    slots: usize,
    /// The regions of `ints`.
    ints: IntRegions,
}

/// The buffers' initial contents.
pub struct Uploaded {
    pub consts: Vec<f64>,
    pub rve: Vec<f64>,
    pub sph: Vec<f64>,
    pub pf: Vec<f64>,
    pub ints: Vec<i32>,
}

/// Pairs of a sphere list that the device stores in row `a` (the second sphere earlier, or the
/// same sphere's image).
fn check_pair(list: &PairList, k: usize) -> Result<(usize, usize)> {
    let (a, b) = (list.a[k] as usize, list.b[k] as usize);
    if b > a {
        return Err(GraniteError::Other(format!("pair ({a}, {b}) stored with its later sphere second")));
    }
    Ok((a, b))
}

/// Most candidates of one sphere of this RVE, as first and as second sphere.
fn longest_row(sim: &DemSim) -> Result<usize> {
    let mut per_sphere = vec![0usize; sim.world.spheres.len()];
    for k in 0..sim.world.pairs.len() {
        let (a, b) = check_pair(&sim.world.pairs, k)?;
        per_sphere[a] += 1;
        per_sphere[b] += 1;
    }
    Ok(per_sphere.into_iter().max().unwrap_or(0))
}

/// Slots per sphere when a sphere has at most `longest` candidates: a row (the pairs where it is
/// first) and an incoming list (where it is second) each hold at most all of them, and 8 more
/// as the packing changes (a row that outgrows its slots gets twice as many).
fn slots_for(longest: usize, min_slots: usize) -> usize {
    (longest + 8).max(MIN_SLOTS).max(min_slots)
}

/// Workgroups of one dispatch along one axis: a buffer set holds at most this many RVEs.
const MOST_RVES_A_SET: usize = 65535;

/// Bytes of the largest buffer of a set of `rves` RVEs holding `spheres` spheres in rows of
/// `slots` slots.
fn largest_buffer(rves: usize, spheres: usize, slots: usize) -> u64 {
    let slot_count = (spheres * slots) as u64;
    let ints = 4 * IntRegions::of(spheres, slots).len as u64;
    let pf = 8 * PF_STRIDE as u64 * slot_count;
    let sph = 8 * (SPH_STRIDE * spheres) as u64;
    let rve = 8 * (RVE_STRIDE * rves) as u64;
    ints.max(pf).max(sph).max(rve)
}

/// The RVEs split into consecutive sets whose buffers each stay within `limit` bytes (the
/// adapter's largest binding and buffer), with at least `min_slots` slots per sphere.
pub fn split(rves: &[DemSim], min_slots: usize, limit: u64) -> Result<Vec<std::ops::Range<usize>>> {
    let mut sets = Vec::new();
    let (mut from, mut spheres, mut longest) = (0, 0, 0);
    for (r, sim) in rves.iter().enumerate() {
        let (n, l) = (sim.world.spheres.len(), longest_row(sim)?);
        let alone = largest_buffer(1, n, slots_for(l, min_slots));
        if alone > limit {
            return Err(GraniteError::Setup(format!(
                "device \"gpu\": RVE {r} ({n} spheres, {} pair slots each) needs a buffer of {alone} bytes, more than the \
                 {limit} bytes the adapter binds at once (GRANITE_GPU_MAX_BINDING may lower it, never raise it); run \
                 it with device \"cpu\"",
                slots_for(l, min_slots)
            )));
        }
        let grown = largest_buffer(r + 1 - from, spheres + n, slots_for(longest.max(l), min_slots));
        if r > from && (grown > limit || r - from == MOST_RVES_A_SET) {
            sets.push(from..r);
            (from, spheres, longest) = (r, 0, 0);
        }
        spheres += n;
        longest = longest.max(l);
    }
    if from < rves.len() {
        sets.push(from..rves.len());
    }
    Ok(sets)
}

impl Layout {
    /// The layout of these RVEs (one buffer set), with at least `min_slots` slots per sphere.
    pub fn new(rves: &[DemSim], min_slots: usize) -> Result<Layout> {
        let mut first = vec![0];
        let mut longest = 0;
        for sim in rves {
            first.push(first.last().copied().unwrap_or(0) + sim.world.spheres.len());
            longest = longest.max(longest_row(sim)?);
        }
        let slots = slots_for(longest, min_slots);
        let spheres = *first.last().unwrap_or(&0);
        let ints = IntRegions::of(spheres, slots);
        if ints.len > i32::MAX as usize || spheres * slots * PF_STRIDE > u32::MAX as usize {
            return Err(GraniteError::Setup(format!(
                "device \"gpu\": {spheres} RVE spheres with {slots} pair slots each are more than one buffer addresses"
            )));
        }
        Ok(Layout { first, slots, ints })
    }

    fn slot(&self, r: usize, i: usize, k: usize) -> usize {
        (self.first[r] + i) * self.slots + k
    }

    /// The buffers' contents for these RVEs, a dispatch taking at most `chunk` steps.
    pub fn upload(&self, rves: &[DemSim], law: &LawConstants, dispatching: Dispatching) -> Result<Uploaded> {
        let spheres = *self.first.last().unwrap_or(&0);
        let slot_count = spheres * self.slots;
        let mut consts = vec![0.0; CONSTS];
        for (at, v) in [
            (Const::Slots, self.slots as f64),
            (Const::Rows, self.ints.rows as f64),
            (Const::RebuiltRows, self.ints.rebuilt_rows as f64),
            (Const::Incoming, self.ints.incoming as f64),
            (Const::IncomingRebuilt, self.ints.incoming_rebuilt as f64),
            (Const::Counts, self.ints.counts as f64),
            (Const::Items, self.ints.items as f64),
            (Const::Skin, law.skin),
            (Const::Damping, law.damping),
            (Const::Chunk, f64::from(dispatching.chunk)),
            (Const::Rebuilds, f64::from(dispatching.rebuilds)),
            (Const::ForceRebuild, if dispatching.force_rebuild { 1.0 } else { 0.0 }),
        ] {
            consts[at as usize] = v;
        }
        consts[Const::LawFirst as usize..][..law.law.constants.len()].copy_from_slice(&law.law.constants);
        let mut rve = vec![0.0; rves.len() * RVE_STRIDE];
        let mut sph = vec![0.0; spheres * SPH_STRIDE];
        let mut pf = vec![0.0; slot_count * PF_STRIDE];
        let mut ints = vec![0i32; self.ints.len];
        for (r, sim) in rves.iter().enumerate() {
            let rec = &mut rve[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
            let cell = sim.world.cell.as_ref().ok_or_else(|| GraniteError::Other("an RVE without a cell".into()))?;
            let state = sim.verlet_state();
            let h_build = state.h_at_build.unwrap_or(cell.h);
            for a in 0..3 {
                for b in 0..3 {
                    rec[Rec::H as usize + 3 * a + b] = cell.h[(a, b)];
                    rec[Rec::HBuild as usize + 3 * a + b] = h_build[(a, b)];
                }
            }
            let s = &sim.world.spheres;
            rec[Rec::Dt as usize] = sim.world.dt;
            rec[Rec::First as usize] = self.first[r] as f64;
            rec[Rec::Count as usize] = s.len() as f64;
            rec[Rec::Rebuild as usize] = if state.needs_rebuild { 1.0 } else { 0.0 };
            rec[Rec::RMax as usize] = s.largest_radius();
            rec[Rec::RMin as usize] = s.smallest_radius();
            rec[Rec::Time as usize] = sim.world.time;
            rec[Rec::Step as usize] = sim.world.step as f64;
            rec[Rec::Rebuilds as usize] = state.rebuilds as f64;
            rec[Rec::Flips as usize] = cell.flips as f64;
            for i in 0..s.len() {
                let o = &mut sph[(self.first[r] + i) * SPH_STRIDE..][..SPH_STRIDE];
                o[0..3].copy_from_slice(&s.x[i]);
                o[3..6].copy_from_slice(&s.v[i]);
                o[6..9].copy_from_slice(&s.w[i]);
                o[9..12].copy_from_slice(state.x_at_build.get(i).unwrap_or(&s.x[i]));
                o[12] = s.radius[i];
                o[13] = s.mass[i];
                o[14] = s.inertia[i];
            }
            let list = &sim.world.pairs;
            let hs = list.history_stride;
            let mut own = vec![0usize; s.len()];
            let mut incoming: Vec<Vec<usize>> = vec![Vec::new(); s.len()];
            for k in 0..list.len() {
                let (a, b) = check_pair(list, k)?;
                let slot = self.slot(r, a, own[a]);
                own[a] += 1;
                incoming[b].push(slot);
                let p = &mut ints[self.ints.rows + 4 * slot..][..4];
                p[0] = b as i32;
                p[1..4].copy_from_slice(&list.shift[k]);
                let f = &mut pf[slot * PF_STRIDE..][..PF_STRIDE];
                let history = &list.history[k * hs..(k + 1) * hs];
                f[..hs.min(7)].copy_from_slice(&history[..hs.min(7)]);
                f[PF_TOUCH] = if list.touching[k] { 1.0 } else { 0.0 };
                f[PF_FORCE..PF_FORCE + 3].copy_from_slice(&list.force[k]);
            }
            for i in 0..s.len() {
                let c = self.ints.counts + 8 * (self.first[r] + i);
                ints[c] = own[i] as i32;
                ints[c + 1] = incoming[i].len() as i32;
                for (k, &slot) in incoming[i].iter().enumerate() {
                    ints[self.ints.incoming + self.slot(r, i, k)] = slot as i32;
                }
            }
        }
        Ok(Uploaded { consts, rve, sph, pf, ints })
    }

    /// Writes the device's state into the host's RVEs.
    pub fn download(&self, rves: &mut [DemSim], records: &[f64], sph: &[f64], pf: &[f64], ints: &[i32]) -> Result<()> {
        for (r, sim) in rves.iter_mut().enumerate() {
            let rec = &records[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
            let matrix = |at: Rec| Matrix3::from_fn(|a, b| rec[at as usize + 3 * a + b]);
            let n = sim.world.spheres.len();
            let mut x_at_build = Vec::with_capacity(n);
            for i in 0..n {
                let o = &sph[(self.first[r] + i) * SPH_STRIDE..][..SPH_STRIDE];
                sim.world.spheres.x[i] = [o[0], o[1], o[2]];
                sim.world.spheres.v[i] = [o[3], o[4], o[5]];
                sim.world.spheres.w[i] = [o[6], o[7], o[8]];
                x_at_build.push([o[9], o[10], o[11]]);
            }
            if let Some(cell) = sim.world.cell.as_mut() {
                cell.h = matrix(Rec::H);
                cell.flips = rec[Rec::Flips as usize] as u64;
            }
            sim.world.time = rec[Rec::Time as usize];
            sim.world.step = rec[Rec::Step as usize] as u64;
            sim.set_verlet_state(VerletState {
                x_at_build,
                h_at_build: Some(matrix(Rec::HBuild)),
                needs_rebuild: rec[Rec::Rebuild as usize] != 0.0,
                rebuilds: rec[Rec::Rebuilds as usize] as u64,
            });
            // The rows as one list sorted by (a, b, shift), parameters set by the law as the CPU's
            // merge sets them.
            let mut found = Vec::new();
            for a in 0..n {
                let rows = ints[self.ints.counts + 8 * (self.first[r] + a)] as usize;
                for k in 0..rows {
                    let slot = self.slot(r, a, k);
                    let p = &ints[self.ints.rows + 4 * slot..][..4];
                    found.push((a as u32, p[0] as u32, [p[1], p[2], p[3]], slot));
                }
            }
            found.sort_by_key(|&(a, b, shift, _)| (a, b, shift));
            let (ps, hs) = sim.world.pair_strides();
            let law =
                sim.world.laws.first().cloned().ok_or_else(|| GraniteError::Other("an RVE without a law".into()))?;
            let mut list = PairList { param_stride: ps, history_stride: hs, ..Default::default() };
            for (a, b, shift, slot) in found {
                let f = &pf[slot * PF_STRIDE..][..PF_STRIDE];
                list.a.push(a);
                list.b.push(b);
                list.shift.push(shift);
                list.law.push(0);
                let mut params = vec![0.0; ps];
                law.init_pair(&sim.world.info_for(a as usize, b as usize, false), &mut params);
                list.params.extend(params);
                let mut history = vec![0.0; hs];
                let kept = hs.min(7);
                history[..kept].copy_from_slice(&f[..kept]);
                list.history.extend(history);
                list.touching.push(f[PF_TOUCH] != 0.0);
                list.force.push([f[PF_FORCE], f[PF_FORCE + 1], f[PF_FORCE + 2]]);
            }
            sim.world.pairs = list;
        }
        Ok(())
    }

    pub fn slots(&self) -> usize {
        self.slots
    }

    /// Whether RVE `r` failed for want of pair slots (it can go on with more).
    pub fn out_of_slots(&self, records: &[f64], r: usize) -> bool {
        let code = records[r * RVE_STRIDE + Rec::Error as usize];
        Failure::from_code(code).is_some_and(|f| matches!(f, Failure::TooManyPairs))
    }

    /// Whether RVE `r` took all the steps of its order, or failed.
    pub fn finished(&self, records: &[f64], r: usize) -> bool {
        let rec = &records[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
        let total = rec[Rec::Steps as usize] + if rec[Rec::LastDt as usize] > 0.0 { 1.0 } else { 0.0 };
        rec[Rec::Error as usize] != 0.0 || rec[Rec::Taken as usize] >= total
    }

    /// What RVE `r` reported.
    pub fn report(&self, records: &[f64], r: usize) -> RveReport {
        let rec = &records[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
        let count = |at: Rec| rec[at as usize] as usize;
        let stress = std::array::from_fn(|k| rec[Rec::Stress as usize + k]);
        RveReport {
            stress,
            cell: Matrix3::from_fn(|a, b| rec[Rec::H as usize + 3 * a + b]),
            contacts: count(Rec::Contacts),
            contact_ends: count(Rec::Ends),
            rattlers: count(Rec::Rattlers),
            floaters: count(Rec::Floaters),
            steps: rec[Rec::Taken as usize] as u64,
            failure: Failure::from_code(rec[Rec::Error as usize])
                .map(|f| f.describe(rec[Rec::ErrorValue as usize], self.slots)),
            events: Vec::new(),
        }
    }
}
