//! The device buffers' layout (`rve.wgsl`), filled from the host's RVEs and read back into them.

use granite_core::dem::cell::CellUpdate;
use granite_core::dem::contacts::PairList;
use granite_core::dem::sim::VerletState;
use granite_core::dem::DemSim;
use granite_core::ext::{DeviceLaw, RveReport};
use granite_core::{GraniteError, Result};
use nalgebra::Matrix3;

pub const RVE_STRIDE: usize = 72;
/// Per sphere: x, v, w, x at the last rebuild, radius, mass, inertia.
const SPH_STRIDE: usize = 16;
/// Most history values a pair keeps on the device.
const MOST_HISTORY: usize = 7;
/// Per pair, apart from its history: the force on the first sphere, the torques on both.
const FORCE_STRIDE: usize = 9;
const PF_FORCE: usize = 0;
const PF_TA: usize = 3;
const PF_TB: usize = 6;
/// Per sphere in `ints`: its row's length, its incoming list's length, the cell images it was
/// wrapped by (3), its row's first pair, its cell, its incoming list's first entry, and while
/// rebuilding its new row's length and first pair.
const CNT_STRIDE: usize = 10;

/// Indices into the batch's constants (`consts`).
#[derive(Clone, Copy)]
enum Const {
    /// Values per pair in each history half: the law's history, then whether it touches.
    HistoryStride,
    /// Pair places of the whole set (one half's length).
    PairRoom,
    /// Offsets into `ints`: the pairs' entries (4 per pair: second sphere, shift; two halves),
    /// each sphere's incoming list (1 per pair: the pairs where it is second), per sphere its
    /// counts (`CNT_STRIDE`), the sphere ids sorted by cell during a rebuild (1 per sphere).
    Entries,
    Incoming,
    Counts,
    Items,
    /// Offset into `pf` of the pairs' forces (the two history halves come first).
    Forces,
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

/// Declares the fields of an RVE's record: `Rec`, each field's offset, and the name the kernel
/// knows it by (`wgsl_constants` writes them).
macro_rules! record_fields {
    ($($(#[$doc:meta])* $field:ident = $at:literal => $name:literal,)*) => {
        /// Offsets into an RVE's record.
        #[derive(Clone, Copy)]
        pub enum Rec {
            $($(#[$doc])* $field = $at,)*
        }
        /// Each field of the record with its name in the kernel.
        const RECORD_NAMES: &[(&str, Rec)] = &[$(($name, Rec::$field),)*];
    };
}

record_fields! {
    /// The cell matrix, row-major.
    H = 0 => "R_H",
    /// The cell matrix at the last rebuild.
    HBuild = 9 => "R_HB",
    /// The velocity gradient of this call.
    L = 18 => "R_L",
    Dt = 27 => "R_DT",
    /// Full steps of this call.
    Steps = 28 => "R_STEPS",
    /// A shorter last step, or 0.
    LastDt = 29 => "R_LAST_DT",
    /// First sphere and spheres.
    First = 30 => "R_FIRST",
    Count = 31 => "R_COUNT",
    /// The lists must be rebuilt before the next step.
    Rebuild = 32 => "R_REBUILD",
    RMax = 33 => "R_RMAX",
    RMin = 34 => "R_RMIN",
    /// 0, or a `Failure` code.
    Error = 35 => "R_ERROR",
    ErrorValue = 36 => "R_ERROR_VALUE",
    Time = 37 => "R_TIME",
    Step = 38 => "R_STEP",
    Rebuilds = 39 => "R_REBUILDS",
    Flips = 40 => "R_FLIPS",
    /// Love-Weber stress, Voigt, tension positive.
    Stress = 41 => "R_STRESS",
    Contacts = 47 => "R_CONTACTS",
    Ends = 48 => "R_ENDS",
    Rattlers = 49 => "R_RATTLERS",
    Floaters = 50 => "R_FLOATERS",
    /// Steps taken by this call (its dispatches so far).
    Taken = 51 => "R_TAKEN",
    /// In record w: the RVE workgroup w steps (the longest orders first).
    Queue = 52 => "R_QUEUE",
    /// Distance tests of the candidate searches (all rebuilds so far).
    Tests = 53 => "R_TESTS",
    /// The RVE's first pair place in the set, and its places.
    PairFirst = 54 => "R_PAIR_FIRST",
    PairRoom = 55 => "R_PAIR_ROOM",
    /// Which history and entries half holds the current pairs (0 or 1).
    Half = 56 => "R_HALF",
    /// Candidate pairs in the current lists.
    Pairs = 57 => "R_PAIRS",
    /// The time-step check (`DemWorld::check_time_step`): the step of the last (-1: check at
    /// the next step), whether it was said; then what this call's first check above the bound
    /// found (limit 0: none): the limit, its step and time, the sphere (index) and its contacts,
    /// and whether it is to be said.
    DtLast = 58 => "R_DT_LAST",
    DtWarned = 59 => "R_DT_WARNED",
    DtLimit = 60 => "R_DT_LIMIT",
    DtStep = 61 => "R_DT_STEP",
    DtTime = 62 => "R_DT_TIME",
    DtSphere = 63 => "R_DT_SPHERE",
    DtContacts = 64 => "R_DT_CONTACTS",
    DtSay = 65 => "R_DT_SAY",
    /// How the fluctuations follow the cell's field (`CellUpdate`: 0 SLLOD, 1 Newton, 2 YADE).
    Update = 66 => "R_UPDATE",
}

/// The constants the kernel is written against, as WGSL (put before `rve.wgsl`).
pub fn wgsl_constants() -> String {
    use Const as C;
    let u = [
        ("C_HS", C::HistoryStride as usize),
        ("C_ROOM", C::PairRoom as usize),
        ("C_ENTRIES", C::Entries as usize),
        ("C_INC", C::Incoming as usize),
        ("C_CNT", C::Counts as usize),
        ("C_ITEMS", C::Items as usize),
        ("C_FORCES", C::Forces as usize),
        ("C_SKIN", C::Skin as usize),
        ("C_DAMPING", C::Damping as usize),
        ("C_CHUNK", C::Chunk as usize),
        ("C_REBUILDS", C::Rebuilds as usize),
        ("C_FORCE_REBUILD", C::ForceRebuild as usize),
        ("C_LAW_FIRST", C::LawFirst as usize),
        ("N_CONSTS", CONSTS),
        ("RVE_STRIDE", RVE_STRIDE),
        ("SPH_STRIDE", SPH_STRIDE),
        ("FORCE_STRIDE", FORCE_STRIDE),
        ("PF_FORCE", PF_FORCE),
        ("PF_TA", PF_TA),
        ("PF_TB", PF_TB),
        ("CNT_STRIDE", CNT_STRIDE),
    ];
    let fields = RECORD_NAMES.iter().map(|&(name, field)| (name, field as usize));
    let mut out: String = u.into_iter().chain(fields).map(|(name, v)| format!("const {name}: u32 = {v}u;\n")).collect();
    for (name, f) in [
        ("FAIL_TOO_FAST", Failure::TooFast),
        ("FAIL_NOT_FINITE", Failure::NotFinite),
        ("FAIL_TOO_MANY_PAIRS", Failure::TooManyPairs),
        ("FAIL_CELL_COLLAPSED", Failure::CellCollapsed),
    ] {
        out += &format!("const {name}: f64 = {}.0lf;\n", f as u32);
    }
    out += &format!("const CHECK_EVERY: f64 = {}.0lf;\n", granite_core::dem::stability::CHECK_EVERY);
    out
}

/// Why an RVE stopped on the device (the kernel's FAIL_ codes).
#[derive(Debug, Clone, Copy)]
pub enum Failure {
    TooFast = 1,
    NotFinite = 2,
    TooManyPairs = 3,
    CellCollapsed = 4,
}

impl Failure {
    fn from_code(code: f64) -> Option<Failure> {
        [Failure::TooFast, Failure::NotFinite, Failure::TooManyPairs, Failure::CellCollapsed]
            .into_iter()
            .find(|&f| f as u32 as f64 == code)
    }
}

/// A time-step check on the device that found the time step above the contacts' bound.
pub struct TimeStepAbove {
    pub step: u64,
    pub time: f64,
    pub dt: f64,
    pub limit: f64,
    pub sphere: usize,
    pub contacts: u32,
    pub say: bool,
}

/// The contact law the kernel runs, with its constants (one per batch).
#[derive(Debug, Clone, PartialEq)]
pub struct LawConstants {
    pub law: DeviceLaw,
    /// History values a pair keeps on the device.
    history: usize,
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
        let [law] = &sim.world.contacts.laws[..] else {
            return refuse("has several contact laws (the device runs one)");
        };
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
        let history = law.history_count().min(MOST_HISTORY);
        Ok(LawConstants { law: form, history, skin: sim.skin, damping: sim.world.damping })
    }
}

/// Where each region of `ints` starts (see `Const::Entries`), and its length.
struct IntRegions {
    entries: usize,
    incoming: usize,
    counts: usize,
    items: usize,
    len: usize,
}

impl IntRegions {
    fn of(spheres: usize, pairs: usize) -> IntRegions {
        let entries = 0;
        let incoming = entries + 2 * 4 * pairs;
        let counts = incoming + pairs;
        let items = counts + CNT_STRIDE * spheres;
        IntRegions { entries, incoming, counts, items, len: items + spheres }
    }
}

/// Where each RVE's spheres and pairs lie in the buffers. An RVE's pairs are one array in the
/// pairs' order (each sphere's row after the last), with room to grow; `pf` holds two halves of
/// pair history (a rebuild writes the other half), then the forces.
pub struct Layout {
    /// First sphere of each RVE, and one past the last.
    first: Vec<usize>,
    /// First pair place of each RVE, and one past the last.
    pair_first: Vec<usize>,
    /// Values per pair in a history half: the law's history, then whether it touches.
    history_stride: usize,
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
    /// Per sphere, a counter the kernel uses while it builds the incoming lists.
    pub tally: Vec<u32>,
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

/// Pair places for an RVE of `spheres` spheres holding `pairs` candidate pairs, whose lists
/// needed `least` places at most so far: a quarter more, and some, for the lists to grow between
/// rebuilds; a list with no pairs yet (never searched) gets four a sphere. Lists that outgrow
/// their room stop the RVE before the rebuild, and the host lays it out again with more.
pub fn room_for(spheres: usize, pairs: usize, least: usize) -> usize {
    let known = pairs.max(least);
    let known = if known == 0 { 4 * spheres } else { known };
    known + known / 4 + 64
}

/// Workgroups of one dispatch along one axis: a buffer set holds at most this many RVEs.
const MOST_RVES_A_SET: usize = 65535;

/// Bytes of each buffer of a set of `rves` RVEs holding `spheres` spheres and `pairs` pair
/// places, history `history_stride` values a pair: ints, pf, sph, rve, tally.
fn buffer_bytes(rves: usize, spheres: usize, pairs: usize, history_stride: usize) -> [u64; 5] {
    let ints = 4 * IntRegions::of(spheres, pairs).len as u64;
    let pf = 8 * ((2 * history_stride + FORCE_STRIDE) * pairs) as u64;
    let sph = 8 * (SPH_STRIDE * spheres) as u64;
    let rve = 8 * (RVE_STRIDE * rves) as u64;
    [ints, pf, sph, rve, 4 * spheres as u64]
}

/// The pair places of each RVE (see `room_for`), `least[r]` places at least.
pub fn rooms(rves: &[DemSim], least: &[usize]) -> Vec<usize> {
    rves.iter()
        .enumerate()
        .map(|(r, sim)| {
            room_for(sim.world.spheres.len(), sim.world.contacts.spheres.len(), least.get(r).copied().unwrap_or(0))
        })
        .collect()
}

/// The RVEs split into consecutive sets whose buffers each stay within `limit` bytes (the
/// adapter's largest binding and buffer), RVE r with `rooms[r]` pair places.
pub fn split(rves: &[DemSim], rooms: &[usize], law: &LawConstants, limit: u64) -> Result<Vec<std::ops::Range<usize>>> {
    let stride = law.history + 1;
    let largest = |rves, spheres, pairs| buffer_bytes(rves, spheres, pairs, stride).into_iter().max().unwrap_or(0);
    let mut sets = Vec::new();
    let (mut from, mut spheres, mut pairs) = (0, 0, 0);
    for (r, sim) in rves.iter().enumerate() {
        let (n, room) = (sim.world.spheres.len(), rooms[r]);
        let alone = largest(1, n, room);
        if alone > limit {
            return Err(GraniteError::Setup(format!(
                "device \"gpu\": RVE {r} ({n} spheres, room for {room} candidate pairs) needs a buffer of {alone} \
                 bytes, more than the {limit} bytes the adapter binds at once (GRANITE_GPU_MAX_BINDING may lower it, \
                 never raise it); run it with device \"cpu\""
            )));
        }
        if r > from && (largest(r + 1 - from, spheres + n, pairs + room) > limit || r - from == MOST_RVES_A_SET) {
            sets.push(from..r);
            (from, spheres, pairs) = (r, 0, 0);
        }
        spheres += n;
        pairs += room;
    }
    if from < rves.len() {
        sets.push(from..rves.len());
    }
    Ok(sets)
}

impl Layout {
    /// The layout of these RVEs (one buffer set), RVE r with `rooms[r]` pair places.
    pub fn new(rves: &[DemSim], rooms: &[usize], law: &LawConstants) -> Result<Layout> {
        let mut first = vec![0];
        let mut pair_first = vec![0];
        for (sim, room) in rves.iter().zip(rooms) {
            first.push(first.last().copied().unwrap_or(0) + sim.world.spheres.len());
            pair_first.push(pair_first.last().copied().unwrap_or(0) + room);
        }
        let spheres = *first.last().unwrap_or(&0);
        let pairs = *pair_first.last().unwrap_or(&0);
        let history_stride = law.history + 1;
        let ints = IntRegions::of(spheres, pairs);
        if ints.len > i32::MAX as usize || pairs * (2 * history_stride + FORCE_STRIDE) > u32::MAX as usize {
            return Err(GraniteError::Setup(format!(
                "device \"gpu\": {spheres} RVE spheres with room for {pairs} pairs are more than one buffer addresses"
            )));
        }
        Ok(Layout { first, pair_first, history_stride, ints })
    }

    /// Where pair place `q` of RVE `r` in history half `half` starts in `pf`.
    fn history_at(&self, half: usize, r: usize, q: usize) -> usize {
        (half * self.pairs() + self.pair_first[r] + q) * self.history_stride
    }

    fn entry_at(&self, half: usize, r: usize, q: usize) -> usize {
        self.ints.entries + (half * self.pairs() + self.pair_first[r] + q) * 4
    }

    fn force_at(&self, r: usize, q: usize) -> usize {
        2 * self.pairs() * self.history_stride + (self.pair_first[r] + q) * FORCE_STRIDE
    }

    fn counts_at(&self, r: usize, i: usize) -> usize {
        self.ints.counts + (self.first[r] + i) * CNT_STRIDE
    }

    fn pairs(&self) -> usize {
        *self.pair_first.last().unwrap_or(&0)
    }

    /// The buffers' contents for these RVEs, a dispatch taking at most `chunk` steps.
    pub fn upload(&self, rves: &[DemSim], law: &LawConstants, dispatching: Dispatching) -> Result<Uploaded> {
        let spheres = *self.first.last().unwrap_or(&0);
        let pairs = self.pairs();
        let mut consts = vec![0.0; CONSTS];
        for (at, v) in [
            (Const::HistoryStride, self.history_stride as f64),
            (Const::PairRoom, pairs as f64),
            (Const::Entries, self.ints.entries as f64),
            (Const::Incoming, self.ints.incoming as f64),
            (Const::Counts, self.ints.counts as f64),
            (Const::Items, self.ints.items as f64),
            (Const::Forces, (2 * pairs * self.history_stride) as f64),
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
        let mut pf = vec![0.0; pairs * (2 * self.history_stride + FORCE_STRIDE)];
        let mut ints = vec![0i32; self.ints.len];
        let kept = self.history_stride - 1;
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
            let list = &sim.world.contacts.spheres;
            let room = self.pair_first[r + 1] - self.pair_first[r];
            if list.len() > room {
                return Err(GraniteError::Other(format!("RVE {r}: {} pairs in room for {room}", list.len())));
            }
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
            rec[Rec::Update as usize] = match cell.update {
                CellUpdate::Sllod => 0.0,
                CellUpdate::Newton => 1.0,
                CellUpdate::Yade => 2.0,
            };
            rec[Rec::PairFirst as usize] = self.pair_first[r] as f64;
            rec[Rec::PairRoom as usize] = room as f64;
            rec[Rec::Half as usize] = 0.0;
            rec[Rec::Pairs as usize] = list.len() as f64;
            let (last_check, warned) = sim.world.time_step_check_state();
            rec[Rec::DtLast as usize] = last_check.map_or(-1.0, |s| s as f64);
            rec[Rec::DtWarned as usize] = if warned { 1.0 } else { 0.0 };
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
            // The list is in its first spheres' order: each sphere's row is a run of it, and its
            // incoming list the pairs where it is second, in list order.
            let hs = list.history_stride;
            let (mut row_len, mut incoming_len) = (vec![0usize; s.len()], vec![0usize; s.len()]);
            for k in 0..list.len() {
                let (a, b) = check_pair(list, k)?;
                if k > 0 && list.a[k - 1] > list.a[k] {
                    return Err(GraniteError::Other(format!(
                        "RVE {r}: its pair list is not in its first spheres' order"
                    )));
                }
                row_len[a] += 1;
                incoming_len[b] += 1;
                let p = &mut ints[self.entry_at(0, r, k)..][..4];
                p[0] = b as i32;
                p[1..4].copy_from_slice(&list.shift[k]);
                let h = &mut pf[self.history_at(0, r, k)..][..self.history_stride];
                let history = &list.history[k * hs..(k + 1) * hs];
                h[..hs.min(kept)].copy_from_slice(&history[..hs.min(kept)]);
                h[kept] = if list.touching[k] { 1.0 } else { 0.0 };
                pf[self.force_at(r, k) + PF_FORCE..][..3].copy_from_slice(&list.force[k]);
            }
            let (mut row_start, mut incoming_start) = (0, 0);
            for i in 0..s.len() {
                let c = self.counts_at(r, i);
                ints[c] = row_len[i] as i32;
                ints[c + 1] = incoming_len[i] as i32;
                ints[c + 5] = row_start as i32;
                ints[c + 7] = incoming_start as i32;
                row_start += row_len[i];
                incoming_start += incoming_len[i];
            }
            // Each incoming list filled from its start, in list order.
            incoming_len.iter_mut().for_each(|n| *n = 0);
            for k in 0..list.len() {
                let b = list.b[k] as usize;
                let at = ints[self.counts_at(r, b) + 7] as usize + incoming_len[b];
                ints[self.ints.incoming + self.pair_first[r] + at] = k as i32;
                incoming_len[b] += 1;
            }
        }
        // (one counter at least: a buffer bound is never empty)
        Ok(Uploaded { consts, rve, sph, pf, ints, tally: vec![0; spheres.max(1)] })
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
            let last_check = rec[Rec::DtLast as usize];
            sim.world.set_time_step_check_state(
                (last_check >= 0.0).then_some(last_check as u64),
                rec[Rec::DtWarned as usize] != 0.0,
            );
            sim.world.step = rec[Rec::Step as usize] as u64;
            sim.set_verlet_state(VerletState {
                x_at_build,
                h_at_build: Some(matrix(Rec::HBuild)),
                needs_rebuild: rec[Rec::Rebuild as usize] != 0.0,
                rebuilds: rec[Rec::Rebuilds as usize] as u64,
            });
            // The rows in their order on the device (the CPU's: by (a, b, shift) since the last
            // rebuild, shifts changed in place by flips), parameters set by the law as the CPU's
            // merge sets them.
            let half = rec[Rec::Half as usize] as usize;
            let (ps, hs) = sim.world.pair_strides();
            let law = sim
                .world
                .contacts
                .laws
                .first()
                .cloned()
                .ok_or_else(|| GraniteError::Other("an RVE without a law".into()))?;
            let mut list = PairList { param_stride: ps, history_stride: hs, ..Default::default() };
            let kept = hs.min(self.history_stride - 1);
            for a in 0..n {
                let c = self.counts_at(r, a);
                let (len, start) = (ints[c] as usize, ints[c + 5] as usize);
                for q in start..start + len {
                    let p = &ints[self.entry_at(half, r, q)..][..4];
                    let b = p[0] as u32;
                    let h = &pf[self.history_at(half, r, q)..][..self.history_stride];
                    let f = &pf[self.force_at(r, q) + PF_FORCE..][..3];
                    list.a.push(a as u32);
                    list.b.push(b);
                    list.shift.push([p[1], p[2], p[3]]);
                    list.law.push(0);
                    let at = list.params.len();
                    list.params.resize(at + ps, 0.0);
                    law.init_pair(&sim.world.info_for(a, b as usize, false), &mut list.params[at..]);
                    let at = list.history.len();
                    list.history.resize(at + hs, 0.0);
                    list.history[at..at + kept].copy_from_slice(&h[..kept]);
                    list.touching.push(h[self.history_stride - 1] != 0.0);
                    list.force.push([f[0], f[1], f[2]]);
                }
            }
            sim.world.contacts.spheres = list;
        }
        Ok(())
    }

    /// The pair places RVE `r` needs, if it stopped for want of them (it can go on with more).
    pub fn pairs_wanted(&self, records: &[f64], r: usize) -> Option<usize> {
        let rec = &records[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
        let failure = Failure::from_code(rec[Rec::Error as usize]);
        failure.is_some_and(|f| matches!(f, Failure::TooManyPairs)).then_some(rec[Rec::ErrorValue as usize] as usize)
    }

    /// Whether RVE `r` took all the steps of its order, or failed.
    pub fn finished(&self, records: &[f64], r: usize) -> bool {
        let rec = &records[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
        let total = rec[Rec::Steps as usize] + if rec[Rec::LastDt as usize] > 0.0 { 1.0 } else { 0.0 };
        rec[Rec::Error as usize] != 0.0 || rec[Rec::Taken as usize] >= total
    }

    /// What the call's first time-step check above the contacts' bound found in RVE `r`: its
    /// step, time and limit, the sphere (index) setting it with its contacts, and whether it is
    /// to be said (the RVE's first).
    pub fn time_step_above(&self, records: &[f64], r: usize) -> Option<TimeStepAbove> {
        let rec = &records[r * RVE_STRIDE..(r + 1) * RVE_STRIDE];
        (rec[Rec::DtLimit as usize] > 0.0).then(|| TimeStepAbove {
            step: rec[Rec::DtStep as usize] as u64,
            time: rec[Rec::DtTime as usize],
            dt: rec[Rec::Dt as usize],
            limit: rec[Rec::DtLimit as usize],
            sphere: rec[Rec::DtSphere as usize] as usize,
            contacts: rec[Rec::DtContacts as usize] as u32,
            say: rec[Rec::DtSay as usize] != 0.0,
        })
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
                .map(|f| f.describe(rec[Rec::ErrorValue as usize], rec[Rec::PairRoom as usize])),
            events: Vec::new(),
        }
    }
}
