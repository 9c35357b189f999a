// The RVEs of one MPM step on the device: one workgroup per periodic DEM sample, persistent over
// all of that sample's DEM steps (thesis eqs. 4.1-4.6). Each step is the CPU engine's step
// (`DemSim::step`) for spheres in a periodic cell: the candidate pairs rebuilt when a sphere or
// the cell has used up the skin, the contact law on every candidate pair, then each sphere's
// loads gathered in a fixed order (no floating-point atomics: a run is byte-identical to itself)
// and the spheres moved with the cell's affine field.
//
// Layout. A pair (a, b, shift) with b < a (or a == b and a positive shift: a sphere and its own
// image in a thin cell) lives in row a. An RVE's pairs are one array in the pairs' order, row
// after row, in the RVE's room of pair places; their entries and history are kept twice (halves):
// a rebuild writes the new lists into the other half, carrying each kept pair's history across,
// and the RVE's record says which half is current. The forces of the step are apart. Each sphere
// also lists the pairs where it is the second sphere ("incoming"), in the pairs' order, so that
// its loads are one sequential sum.

// Invocations per workgroup: the host sets this line for the batch's RVE size (a power of two,
// 64 to 1024).
const WG: u32 = 64u;

// The host puts the layout's constants before this text (`layout::wgsl_constants`): indices into
// `consts` (C_), into an RVE's record (R_, RVE_STRIDE values a record), the strides and fields of
// the sphere, pair and count buffers (SPH_, FORCE_, PF_, CNT_) and the failure codes (FAIL_).
const MAX_IMAGES_ACROSS: f64 = 64.0;
// Most cells of a rebuild's cell list (workgroup memory), cells per sphere at most, and cells
// across the reach.
const MAX_CELLS: u32 = 2048u;
const CELLS_PER_SPHERE: u32 = 2u;
const CELL_SPLIT: f64 = 1.0lf;
// Runs of pairs summed apart in the Love-Weber stress, then added in a tree (as `measures.rs`
// sums them), and the runs of each invocation.
const STRESS_LANES: u32 = 256u;
const LANES_EACH: u32 = max(STRESS_LANES / WG, 1u);

@group(0) @binding(0) var<storage, read> consts: array<f64>;
@group(0) @binding(1) var<storage, read_write> rve: array<f64>;
@group(0) @binding(2) var<storage, read_write> sph: array<f64>;
@group(0) @binding(3) var<storage, read_write> pf: array<f64>;
@group(0) @binding(4) var<storage, read_write> ints: array<i32>;
// Per sphere, the pairs where it is second counted and placed while the incoming lists are built.
@group(0) @binding(5) var<storage, read_write> tally: array<atomic<u32>>;

var<workgroup> w_h: array<f64, 9>;
var<workgroup> w_hn: array<f64, 9>;
var<workgroup> w_inv: array<f64, 9>;
var<workgroup> w_f: array<f64, 9>;
var<workgroup> w_l: array<f64, 9>;
var<workgroup> w_ldt: array<f64, 9>;
var<workgroup> w_minv: array<i32, 9>;
var<workgroup> w_dt: f64;
var<workgroup> w_moved: array<f64, WG>;
var<workgroup> w_bad: array<u32, WG>;
// The call's contact counts (contacts, contact ends, rattlers, floaters) and the stress tree.
var<workgroup> w_totals: array<atomic<u32>, 4>;
var<workgroup> w_tree: array<f64, STRESS_LANES>;
var<workgroup> w_steps: u32;
var<workgroup> w_done: u32;
var<workgroup> w_rebuild: u32;
var<workgroup> w_flip: u32;
var<workgroup> w_fail: u32;
var<workgroup> w_check: u32;
// The cell list of a rebuild: cells along each axis, cells the reach spans on each side, each
// cell's count, then its start, then its end; a scan's partial sums; distance tests made.
var<workgroup> w_dims: vec3<u32>;
var<workgroup> w_reach_cells: vec3<i32>;
var<workgroup> w_cells: array<atomic<u32>, MAX_CELLS>;
var<workgroup> w_scan: array<u32, WG>;
var<workgroup> w_tests: atomic<u32>;

// The batch's constants, copied once per invocation out of `consts` (read in every inner loop).
var<private> pc: array<f64, N_CONSTS>;
var<private> pu: array<u32, N_CONSTS>;
// This RVE's first pair place in the set, and its current half; how its fluctuations follow
// the cell's field (`CellUpdate`: 0 SLLOD, 1 Newton, 2 YADE).
var<private> pair_first: u32;
var<private> half: u32;
var<private> cell_update: u32;

fn cu(i: u32) -> u32 { return pu[i]; }
fn cf(i: u32) -> f64 { return pc[i]; }

fn load3(base: u32) -> vec3<f64> { return vec3<f64>(sph[base], sph[base + 1u], sph[base + 2u]); }
fn store3(base: u32, v: vec3<f64>) { sph[base] = v.x; sph[base + 1u] = v.y; sph[base + 2u] = v.z; }
fn pf3(base: u32) -> vec3<f64> { return vec3<f64>(pf[base], pf[base + 1u], pf[base + 2u]); }
fn set_pf3(base: u32, v: vec3<f64>) { pf[base] = v.x; pf[base + 1u] = v.y; pf[base + 2u] = v.z; }

// Where pair q of this RVE (its place in the room) keeps, in half h, its entry (second sphere,
// shift) and its history (the law's, then whether it touches); its forces; an incoming entry.
fn entry_at(h: u32, q: u32) -> u32 { return cu(C_ENTRIES) + (h * cu(C_ROOM) + pair_first + q) * 4u; }
fn history_at(h: u32, q: u32) -> u32 { return (h * cu(C_ROOM) + pair_first + q) * cu(C_HS); }
fn touch_at(q: u32) -> u32 { return history_at(half, q) + cu(C_HS) - 1u; }
fn force_at(q: u32) -> u32 { return cu(C_FORCES) + (pair_first + q) * FORCE_STRIDE; }
fn incoming_at(k: u32) -> u32 { return cu(C_INC) + pair_first + k; }

// A row-major 3x3 times a vector, summed in the order of `granite_core::math::mat_vec`.
fn mat_vec(m: array<f64, 9>, v: vec3<f64>) -> vec3<f64> {
    return vec3<f64>(
        m[0] * v.x + m[1] * v.y + m[2] * v.z,
        m[3] * v.x + m[4] * v.y + m[5] * v.z,
        m[6] * v.x + m[7] * v.y + m[8] * v.z);
}
fn image(n: vec3<i32>) -> vec3<f64> {
    if (all(n == vec3<i32>(0))) { return vec3<f64>(0.0lf); }
    return mat_vec(w_h, vec3<f64>(f64(n.x), f64(n.y), f64(n.z)));
}

fn sdot(a: vec3<f64>, b: vec3<f64>) -> f64 { return a.x * b.x + a.y * b.y + a.z * b.z; }
fn scross(a: vec3<f64>, b: vec3<f64>) -> vec3<f64> {
    return vec3<f64>(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

// Inverse of a row-major 3x3 (cofactors over the determinant).
fn inverse3(m: array<f64, 9>) -> array<f64, 9> {
    let c00 = m[4] * m[8] - m[5] * m[7];
    let c01 = m[5] * m[6] - m[3] * m[8];
    let c02 = m[3] * m[7] - m[4] * m[6];
    let det = m[0] * c00 + m[1] * c01 + m[2] * c02;
    let d = 1.0lf / det;
    return array<f64, 9>(
        c00 * d, (m[2] * m[7] - m[1] * m[8]) * d, (m[1] * m[5] - m[2] * m[4]) * d,
        c01 * d, (m[0] * m[8] - m[2] * m[6]) * d, (m[2] * m[3] - m[0] * m[5]) * d,
        c02 * d, (m[1] * m[6] - m[0] * m[7]) * d, (m[0] * m[4] - m[1] * m[3]) * d);
}

fn sph_base(first: u32, i: u32) -> u32 { return (first + i) * SPH_STRIDE; }
// Sphere i's counts: its row's length [0], incoming list's length [1], the images it was wrapped
// by [2..4], its row's first pair [5], its cell [6], its incoming list's first entry [7], and
// while rebuilding its new row's length [8] and first pair [9].
fn cnt_base(first: u32, i: u32) -> u32 { return cu(C_CNT) + (first + i) * CNT_STRIDE; }
fn row_partner(q: u32) -> i32 { return ints[entry_at(half, q)]; }
fn row_shift(q: u32) -> vec3<i32> {
    let b = entry_at(half, q);
    return vec3<i32>(ints[b + 1u], ints[b + 2u], ints[b + 3u]);
}

// Whether a pair of a sphere with its own image is stored under this shift (its first non-zero
// component positive), as the CPU's broad phase keeps it.
fn positive_shift(n: vec3<i32>) -> bool {
    if (n.x != 0) { return n.x > 0; }
    if (n.y != 0) { return n.y > 0; }
    return n.z > 0;
}

// Branch vector of pair (a, b, shift), always from its first sphere: both spheres of a pair then
// decide alike whether it is a candidate.
fn branch(first: u32, a: u32, b: u32, n: vec3<i32>) -> vec3<f64> {
    return (load3(sph_base(first, b)) - load3(sph_base(first, a))) + image(n);
}

// Spring-slider of `tangential.rs`: the spring turned into the contact plane, loaded by the
// tangential relative displacement, capped by Coulomb.
fn beyond_scale(v: vec3<f64>, limit: f64) -> f64 {
    let norm2 = sdot(v, v);
    if (norm2 > limit * limit) {
        let norm = sqrt(norm2);
        return select(0.0lf, limit / norm, norm > 0.0lf);
    }
    return -1.0lf;
}

fn rotate_into_plane(u: vec3<f64>, n: vec3<f64>) -> vec3<f64> {
    let len2 = sdot(u, u);
    if (len2 == 0.0lf) { return u; }
    let t = u - sdot(u, n) * n;
    let t2 = sdot(t, t);
    if (t2 == 0.0lf) { return vec3<f64>(0.0lf); }
    return t * sqrt(len2 / t2);
}

// What a contact law returns: the force and the extra moment on the pair's first sphere. The law
// itself (`fn contact_law`, see `granite_core::ext::DeviceLaw`) comes after this text, supplied by
// the law's plugin; its constants are `law_constant(i)`, its history from `pf[h]` on.
struct Law { force: vec3<f64>, moment: vec3<f64> }

fn law_constant(i: u32) -> f64 { return pc[C_LAW_FIRST + i]; }

// The tangential spring-slider of `tangential.rs` for the pair whose history starts at `pf[h]`:
// the spring turned into the contact plane, loaded by the tangential relative displacement,
// capped at `limit` (Coulomb); returns the tangential force and keeps the spring.
fn spring_slider(h: u32, n: vec3<f64>, rel_v: vec3<f64>, kt: f64, limit: f64, dt: f64) -> vec3<f64> {
    let r = rotate_into_plane(vec3<f64>(pf[h], pf[h + 1u], pf[h + 2u]), n);
    let vt = rel_v - sdot(rel_v, n) * n;
    var s = r + vt * dt;
    var ft = kt * s;
    let scale = beyond_scale(ft, limit);
    if (scale >= 0.0lf) { ft = ft * scale; s = s * scale; }
    pf[h] = s.x; pf[h + 1u] = s.y; pf[h + 2u] = s.z;
    return ft;
}

fn open_contact(q: u32) {
    if (pf[touch_at(q)] == 0.0lf) { return; }
    let h = history_at(half, q);
    for (var e = 0u; e < cu(C_HS); e++) { pf[h + e] = 0.0lf; }
    let f = force_at(q);
    for (var e = 0u; e < FORCE_STRIDE; e++) { pf[f + e] = 0.0lf; }
}

// Contact stage of sphere a's row.
fn contacts_of(first: u32, a: u32, dt: f64) {
    let k_max = u32(ints[cnt_base(first, a)]);
    let row = u32(ints[cnt_base(first, a) + 5u]);
    let sa = sph_base(first, a);
    let xa = load3(sa);
    let va = load3(sa + 3u);
    let wa = load3(sa + 6u);
    let ra = sph[sa + 12u];
    for (var q = row; q < row + k_max; q++) {
        let b = u32(row_partner(q));
        let sb = sph_base(first, b);
        let d = (load3(sb) - xa) + image(row_shift(q));
        let rb = sph[sb + 12u];
        let reach = ra + rb;
        let dist2 = sdot(d, d);
        if (dist2 >= reach * reach) { open_contact(q); continue; }
        let inv2 = 1.0lf / dist2;
        let dist = sqrt(dist2);
        let n = d * (dist * inv2);
        let overlap = reach - dist;
        let la = ra - 0.5lf * overlap;
        let lb = dist - la;
        let wb = load3(sb + 6u);
        let spins = la * wa + lb * wb;
        let rel_v = ((load3(sb + 3u) - va) - scross(spins, n)) + mat_vec(w_l, d);
        let law = contact_law(history_at(half, q), ra, rb, n, overlap, rel_v, wb - wa, dt);
        let nf = scross(n, law.force);
        let p = force_at(q);
        pf[touch_at(q)] = 1.0lf;
        set_pf3(p + PF_FORCE, law.force);
        set_pf3(p + PF_TA, la * nf + law.moment);
        set_pf3(p + PF_TB, lb * nf - law.moment);
    }
}

// YADE's Cundall damping of an acceleration (`motion.rs`).
fn cundall(acc: vec3<f64>, vel: vec3<f64>, damping: f64, dt: f64) -> vec3<f64> {
    let power = acc * (vel + 0.5lf * dt * acc);
    let sign = select(vec3<f64>(-1.0lf), vec3<f64>(1.0lf), power >= vec3<f64>(0.0lf));
    return acc * (vec3<f64>(1.0lf) - damping * sign);
}

// Gathers sphere i's loads and moves it. Returns its squared displacement since the last rebuild
// (-1 if its state is not finite). The sums run in the CPU engine's order (`write_back`): its own
// row's pairs, a pair with its own image taking off its force as it comes, then the pairs where
// it is second, in pair order.
fn move_sphere(first: u32, i: u32, dt: f64) -> f64 {
    let c = cnt_base(first, i);
    var run_f = vec3<f64>(0.0lf);
    var run_t = vec3<f64>(0.0lf);
    var f = vec3<f64>(0.0lf);
    var t = vec3<f64>(0.0lf);
    let row = u32(ints[c + 5u]);
    let row_end = row + u32(ints[c]);
    for (var q = row; q < row_end; q++) {
        if (pf[touch_at(q)] == 0.0lf) { continue; }
        let p = force_at(q);
        run_f += pf3(p + PF_FORCE);
        run_t += pf3(p + PF_TA);
        if (u32(row_partner(q)) == i) { f -= pf3(p + PF_FORCE); t += pf3(p + PF_TB); }
    }
    f += run_f;
    t += run_t;
    let incoming = u32(ints[c + 1u]);
    let base = incoming_at(u32(ints[c + 7u]));
    for (var k = 0u; k < incoming; k++) {
        let q = u32(ints[base + k]);
        // Pairs of the sphere with its own image are summed with its row.
        if (q >= row && q < row_end) { continue; }
        if (pf[touch_at(q)] != 0.0lf) { let p = force_at(q); f -= pf3(p + PF_FORCE); t += pf3(p + PF_TB); }
    }
    let s = sph_base(first, i);
    var x = load3(s);
    var v = load3(s + 3u);
    var w = load3(s + 6u);
    let damping = cf(C_DAMPING);
    let inv_m = 1.0lf / sph[s + 13u];
    let inv_i = 1.0lf / sph[s + 14u];
    v = v + cundall(f * inv_m, v, damping, dt) * dt;
    let moving = v + mat_vec(w_l, x);
    x = x + moving * dt;
    // The field's part of the fluctuation's change (`Motion::advance_free`, whose matrix L dt
    // this is).
    if (cell_update == 0u) { v = v - mat_vec(w_ldt, v); } else if (cell_update == 1u) { v = v - mat_vec(w_ldt, moving); }
    w = w + cundall(t * inv_i, w, damping, dt) * dt;
    store3(s, x);
    store3(s + 3u, v);
    store3(s + 6u, w);
    let d = x - mat_vec(w_f, load3(s + 9u));
    // Finite only if every term is (NaN fails every comparison).
    let check = d.x + d.y + d.z + v.x + v.y + v.z + w.x + w.y + w.z;
    if (!(abs(check) <= 1.7976931348623157e308lf)) { return -1.0lf; }
    return sdot(d, d);
}

// Whether entry (j, n) comes before entry (k, m) in the pairs' order: by sphere, then by
// shift, lexicographically (the CPU's sort of candidates by (a, b, shift)).
fn entry_before(p: vec4<i32>, q: vec4<i32>) -> bool {
    if (p.x != q.x) { return p.x < q.x; }
    if (p.y != q.y) { return p.y < q.y; }
    if (p.z != q.z) { return p.z < q.z; }
    return p.w < q.w;
}

fn entry(at: u32) -> vec4<i32> { return vec4<i32>(ints[at], ints[at + 1u], ints[at + 2u], ints[at + 3u]); }
fn set_entry(at: u32, e: vec4<i32>) { ints[at] = e.x; ints[at + 1u] = e.y; ints[at + 2u] = e.z; ints[at + 3u] = e.w; }

// Sorts `len` entries of 4 ints from `ints[at]` on into the pairs' order (a row is short:
// insertion).
fn sort_entries(at: u32, len: u32) {
    for (var k = 1u; k < len; k++) {
        let e = entry(at + k * 4u);
        var to = k;
        while (to > 0u && entry_before(e, entry(at + (to - 1u) * 4u))) {
            set_entry(at + to * 4u, entry(at + (to - 1u) * 4u));
            to--;
        }
        set_entry(at + to * 4u, e);
    }
}

// The cell list: the first item of cell q and one past its last (after the placement, w_cells
// holds each cell's end).
fn cell_start(q: u32) -> u32 { return select(0u, atomicLoad(&w_cells[max(q, 1u) - 1u]), q > 0u); }
fn cell_end(q: u32) -> u32 { return atomicLoad(&w_cells[q]); }

// Candidate search for sphere i's row (the CPU's `rebuild_candidates`): the spheres of the cells
// within reach of its own, each cell under the image it is met through, that come before it in
// the pairs' order. Counts them, or (`write`) writes them from new pair `start` on in the other
// half; returns how many, and the distance tests made.
fn search_row(first: u32, i: u32, write: bool, start: u32) -> vec2<u32> {
    let skin = cf(C_SKIN);
    let si = sph_base(first, i);
    let ri = sph[si + 12u];
    let c = cnt_base(first, i);
    let dims = vec3<i32>(w_dims);
    let at = ints[c + 6u];
    let own_cell = vec3<i32>(at % dims.x, (at / dims.x) % dims.y, at / (dims.x * dims.y));
    let m = w_reach_cells;
    let items = cu(C_ITEMS) + first;
    let most = u32(ints[c + 8u]);
    var found = 0u;
    var tests = 0u;
    for (var dz = -m.z; dz <= m.z; dz++) {
        for (var dy = -m.y; dy <= m.y; dy++) {
            for (var dx = -m.x; dx <= m.x; dx++) {
                let raw = own_cell + vec3<i32>(dx, dy, dz);
                // The cell (wrapped) and the image it is met through: each offset its own pair.
                let q = ((raw % dims) + dims) % dims;
                let n = (raw - q) / dims;
                let cell = u32(q.x + dims.x * (q.y + dims.y * q.z));
                let end = cell_end(cell);
                for (var t = cell_start(cell); t < end; t++) {
                    let j = u32(ints[items + t]);
                    // The pair as stored: in the row of its later sphere (of a sphere and its
                    // own image, under the positive shift).
                    if (!(j < i || (j == i && positive_shift(n)))) { continue; }
                    tests++;
                    let reach = ri + sph[sph_base(first, j) + 12u] + skin;
                    let d = branch(first, i, j, n);
                    if (sdot(d, d) >= reach * reach) { continue; }
                    if (write && found < most) { set_entry(entry_at(1u - half, start + found), vec4<i32>(i32(j), n)); }
                    found++;
                }
            }
        }
    }
    return vec2<u32>(found, tests);
}

// Sphere i's new row, counted before (`cnt[8]`, placed at `cnt[9]`): written into the other half
// in the pairs' order, each pair kept from the current row with its history (its contact's
// force comes anew at the next step). Returns the distance tests made.
fn write_row(first: u32, i: u32) -> u32 {
    let c = cnt_base(first, i);
    let fresh = u32(ints[c + 8u]);
    let start = u32(ints[c + 9u]);
    let tests = search_row(first, i, true, start).y;
    let other = 1u - half;
    sort_entries(entry_at(other, start), fresh);
    let old = u32(ints[c + 5u]);
    let old_len = u32(ints[c]);
    let hs = cu(C_HS);
    for (var k = 0u; k < fresh; k++) {
        let q = start + k;
        let e = entry(entry_at(other, q));
        var was = -1;
        for (var o = old; o < old + old_len; o++) {
            if (row_partner(o) == e.x && all(row_shift(o) == e.yzw)) { was = i32(o); break; }
        }
        let to = history_at(other, q);
        if (was >= 0) {
            let from_h = history_at(half, u32(was));
            for (var h = 0u; h < hs; h++) { pf[to + h] = pf[from_h + h]; }
        } else {
            for (var h = 0u; h < hs; h++) { pf[to + h] = 0.0lf; }
        }
        let f = force_at(q);
        for (var h = 0u; h < FORCE_STRIDE; h++) { pf[f + h] = 0.0lf; }
    }
    // No other invocation reads this sphere's row while the rows are written.
    ints[c] = i32(fresh);
    ints[c + 5u] = i32(start);
    let si = sph_base(first, i);
    store3(si + 9u, load3(si));
    return tests;
}

// What the invocations before this one hold in all (`mine` each); afterwards w_scan[WG - 1] is
// the workgroup's total. Integers: the same in any order.
fn scan_across(lid: u32, mine: u32) -> u32 {
    w_scan[lid] = mine;
    workgroupBarrier();
    for (var step = 1u; step < WG; step = step * 2u) {
        var add = 0u;
        if (lid >= step) { add = w_scan[lid - step]; }
        workgroupBarrier();
        w_scan[lid] += add;
        workgroupBarrier();
    }
    return w_scan[lid] - mine;
}

// Counts per cell into the cells' starts, in place: each invocation a run of cells, the runs'
// totals scanned across the workgroup.
fn exclusive_scan_cells(lid: u32, cells: u32) {
    let per = (cells + WG - 1u) / WG;
    let lo = min(lid * per, cells);
    let hi = min(lo + per, cells);
    var total = 0u;
    for (var q = lo; q < hi; q++) { total += atomicLoad(&w_cells[q]); }
    var run = scan_across(lid, total);
    for (var q = lo; q < hi; q++) {
        let here = atomicLoad(&w_cells[q]);
        atomicStore(&w_cells[q], run);
        run += here;
    }
    workgroupBarrier();
}

fn barrier_all() {
    storageBarrier();
    workgroupBarrier();
}

fn fail(r: u32, code: f64, value: f64) {
    if (rve[r * RVE_STRIDE + R_ERROR] == 0.0lf) {
        rve[r * RVE_STRIDE + R_ERROR] = code;
        rve[r * RVE_STRIDE + R_ERROR_VALUE] = value;
    }
    w_fail = 1u;
}

// Rebuilds the candidate lists of RVE r: positions wrapped into the cell (pair shifts
// corrected), every row searched anew, the incoming lists resolved.
fn rebuild(r: u32, lid: u32, first: u32, count: u32) {
    let base = r * RVE_STRIDE;
    if (lid == 0u) {
        w_inv = inverse3(w_h);
        // Widths between opposite faces: 1 / |row a of h^-1|.
        let reach = 2.0lf * rve[base + R_RMAX] + cf(C_SKIN);
        for (var a = 0u; a < 3u; a++) {
            let g = sqrt(w_inv[3u * a] * w_inv[3u * a] + w_inv[3u * a + 1u] * w_inv[3u * a + 1u] + w_inv[3u * a + 2u] * w_inv[3u * a + 2u]);
            if (!(MAX_IMAGES_ACROSS >= reach * g)) { fail(r, FAIL_CELL_COLLAPSED, 1.0lf / g); }
            // Cells at least 1/CELL_SPLIT of the reach thick, and the cells on each side that
            // the reach spans (more than CELL_SPLIT in a cell thinner than the reach).
            let across = clamp(floor(CELL_SPLIT / (reach * g)), 1.0lf, 1024.0lf);
            w_dims[a] = u32(across);
        }
        let most = min(MAX_CELLS, max(CELLS_PER_SPHERE * count, 27u));
        while (w_dims.x * w_dims.y * w_dims.z > most) {
            var a = 0u;
            if (w_dims.y > w_dims[a]) { a = 1u; }
            if (w_dims.z > w_dims[a]) { a = 2u; }
            w_dims[a] = max(w_dims[a] / 2u, 1u);
        }
        for (var a = 0u; a < 3u; a++) {
            let g = sqrt(w_inv[3u * a] * w_inv[3u * a] + w_inv[3u * a + 1u] * w_inv[3u * a + 1u] + w_inv[3u * a + 2u] * w_inv[3u * a + 2u]);
            // A hair more than the reach: positions may lie a rounding error outside their cell.
            w_reach_cells[a] = max(i32(ceil(reach * g * f64(w_dims[a]) * 1.000001lf)), 1);
        }
        atomicStore(&w_tests, 0u);
    }
    if (workgroupUniformLoad(&w_fail) != 0u) { return; }
    let dims = w_dims;
    let cells = dims.x * dims.y * dims.z;
    for (var q = lid; q < cells; q += WG) { atomicStore(&w_cells[q], 0u); }
    workgroupBarrier();
    // Positions wrapped into the cell, each sphere's cell counted.
    for (var i = lid; i < count; i += WG) {
        let s = sph_base(first, i);
        var x = load3(s);
        let k = vec3<i32>(floor(mat_vec(w_inv, x)));
        let c = cnt_base(first, i);
        ints[c + 2u] = k.x; ints[c + 3u] = k.y; ints[c + 4u] = k.z;
        if (any(k != vec3<i32>(0))) { x = x - image(k); store3(s, x); }
        // Rounding may leave a reduced coordinate a hair outside [0, 1): the nearest cell.
        let at = vec3<i32>(floor(mat_vec(w_inv, x) * vec3<f64>(dims)));
        let q = vec3<u32>(clamp(at, vec3<i32>(0), vec3<i32>(dims) - vec3<i32>(1)));
        let cell = q.x + dims.x * (q.y + dims.y * q.z);
        ints[c + 6u] = i32(cell);
        atomicAdd(&w_cells[cell], 1u);
    }
    barrier_all();
    exclusive_scan_cells(lid, cells);
    // Sphere ids by cell: placed in any order, then each cell's run sorted (the lists do not
    // depend on the order within a cell; the search reads ids in increasing order all the same).
    let items = cu(C_ITEMS) + first;
    for (var i = lid; i < count; i += WG) {
        let at = atomicAdd(&w_cells[u32(ints[cnt_base(first, i) + 6u])], 1u);
        ints[items + at] = i32(i);
    }
    barrier_all();
    for (var q = lid; q < cells; q += WG) {
        let lo = cell_start(q);
        let end = cell_end(q);
        for (var k = lo + 1u; k < end; k++) {
            let id = ints[items + k];
            var at = k;
            while (at > lo && ints[items + at - 1u] > id) { ints[items + at] = ints[items + at - 1u]; at--; }
            ints[items + at] = id;
        }
    }
    for (var i = lid; i < count; i += WG) {
        let c = cnt_base(first, i);
        let ka = vec3<i32>(ints[c + 2u], ints[c + 3u], ints[c + 4u]);
        let row = u32(ints[c + 5u]);
        for (var q = row; q < row + u32(ints[c]); q++) {
            let p = entry_at(half, q);
            let cb = cnt_base(first, u32(ints[p]));
            ints[p + 1u] += ints[cb + 2u] - ka.x;
            ints[p + 2u] += ints[cb + 3u] - ka.y;
            ints[p + 3u] += ints[cb + 4u] - ka.z;
        }
    }
    barrier_all();
    // Each row counted, the rows placed one after the other in the pairs' order, then written
    // (searched again) into the other half.
    var tests = 0u;
    for (var i = lid; i < count; i += WG) {
        let found = search_row(first, i, false, 0u);
        ints[cnt_base(first, i) + 8u] = i32(found.x);
        tests += found.y;
    }
    barrier_all();
    let per = (count + WG - 1u) / WG;
    let lo = min(lid * per, count);
    let hi = min(lo + per, count);
    var run_len = 0u;
    for (var i = lo; i < hi; i++) { run_len += u32(ints[cnt_base(first, i) + 8u]); }
    var at = scan_across(lid, run_len);
    for (var i = lo; i < hi; i++) {
        let c = cnt_base(first, i);
        ints[c + 9u] = i32(at);
        at += u32(ints[c + 8u]);
    }
    let pairs = workgroupUniformLoad(&w_scan[WG - 1u]);
    // Lists that outgrew the room stay as they were (all valid, history and all) and due for a
    // rebuild: the host gives the RVE more room and it goes on from here.
    if (lid == 0u && pairs > u32(rve[base + R_PAIR_ROOM])) { fail(r, FAIL_TOO_MANY_PAIRS, f64(pairs)); }
    if (workgroupUniformLoad(&w_fail) != 0u) {
        atomicAdd(&w_tests, tests);
        barrier_all();
        if (lid == 0u) { rve[base + R_TESTS] += f64(atomicLoad(&w_tests)); }
        return;
    }
    barrier_all();
    for (var i = lid; i < count; i += WG) { tests += write_row(first, i); }
    atomicAdd(&w_tests, tests);
    barrier_all();
    half = 1u - half;
    // The incoming lists from the rows: each sphere's pairs counted (integers, in any order),
    // the lists placed one after the other, filled in any order, then each sorted into the
    // pairs' order.
    for (var i = lid; i < count; i += WG) {
        let c = cnt_base(first, i);
        let row = u32(ints[c + 5u]);
        for (var q = row; q < row + u32(ints[c]); q++) { atomicAdd(&tally[first + u32(row_partner(q))], 1u); }
    }
    barrier_all();
    var run_in = 0u;
    for (var i = lo; i < hi; i++) {
        let c = cnt_base(first, i);
        ints[c + 1u] = i32(atomicLoad(&tally[first + i]));
        run_in += u32(ints[c + 1u]);
    }
    var at_in = scan_across(lid, run_in);
    for (var i = lo; i < hi; i++) {
        let c = cnt_base(first, i);
        ints[c + 7u] = i32(at_in);
        at_in += u32(ints[c + 1u]);
        atomicStore(&tally[first + i], 0u);
    }
    barrier_all();
    for (var i = lid; i < count; i += WG) {
        let c = cnt_base(first, i);
        let row = u32(ints[c + 5u]);
        for (var q = row; q < row + u32(ints[c]); q++) {
            let b = u32(row_partner(q));
            let k = atomicAdd(&tally[first + b], 1u);
            ints[incoming_at(u32(ints[cnt_base(first, b) + 7u]) + k)] = i32(q);
        }
    }
    barrier_all();
    for (var i = lid; i < count; i += WG) {
        let c = cnt_base(first, i);
        let base_in = incoming_at(u32(ints[c + 7u]));
        for (var k = 1u; k < u32(ints[c + 1u]); k++) {
            let q = ints[base_in + k];
            var to = k;
            while (to > 0u && ints[base_in + to - 1u] > q) { ints[base_in + to] = ints[base_in + to - 1u]; to--; }
            ints[base_in + to] = q;
        }
        atomicStore(&tally[first + i], 0u);
    }
    barrier_all();
    if (lid == 0u) {
        rve[base + R_TESTS] += f64(atomicLoad(&w_tests));
        for (var q = 0u; q < 9u; q++) { rve[base + R_HB + q] = w_h[q]; }
        rve[base + R_REBUILD] = 0.0lf;
        rve[base + R_REBUILDS] += 1.0lf;
        rve[base + R_HALF] = f64(half);
        rve[base + R_PAIRS] = f64(pairs);
    }
    barrier_all();
}

// The time-step check (`DemWorld::check_time_step`, stability.rs). The contacts, linearised
// about this step, make `M q'' = -K q` with six degrees of freedom a sphere; Gershgorin bounds the
// largest eigenvalue of `M^-1/2 K M^-1/2` row by row. Sphere i's rows: its own block (every
// spring of its contacts) and its couplings to the spheres it touches. A spring `K = k_t I +
// (k_n - k_t) n n^T` acts on the contact point's relative displacement, which a sphere's scaled
// motion moves by `B = [I / sqrt(m), -S(arm) / sqrt(I)]` (`S(a) v = a x v`). Returns the largest
// row's bound and the sphere's contacts (bound -1 without contacts).
fn skew_times(a: vec3<f64>, m: mat3x3<f64>) -> mat3x3<f64> {
    return mat3x3<f64>(scross(a, m[0]), scross(a, m[1]), scross(a, m[2]));
}
fn times_skew(m: mat3x3<f64>, a: vec3<f64>) -> mat3x3<f64> {
    return mat3x3<f64>(m * scross(a, vec3<f64>(1.0lf, 0.0lf, 0.0lf)), m * scross(a, vec3<f64>(0.0lf, 1.0lf, 0.0lf)),
        m * scross(a, vec3<f64>(0.0lf, 0.0lf, 1.0lf)));
}
fn row_abs(m: mat3x3<f64>, r: u32) -> f64 { return abs(m[0][r]) + abs(m[1][r]) + abs(m[2][r]); }
fn col_abs(m: mat3x3<f64>, c: u32) -> f64 { return abs(m[c].x) + abs(m[c].y) + abs(m[c].z); }

// The sphere whose row holds pair q (the last whose row starts at or before it).
fn first_sphere_of(first: u32, count: u32, q: u32) -> u32 {
    var lo = 0u;
    var hi = count;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (u32(ints[cnt_base(first, mid) + 5u]) <= q) { lo = mid; } else { hi = mid; }
    }
    return lo;
}

fn stiffness_row(first: u32, count: u32, i: u32) -> vec2<f64> {
    let c = cnt_base(first, i);
    let own_len = u32(ints[c]);
    let row = u32(ints[c + 5u]);
    let incoming = u32(ints[c + 1u]);
    let inc0 = incoming_at(u32(ints[c + 7u]));
    let si = sph_base(first, i);
    let alpha = 1.0lf / sqrt(sph[si + 13u]);
    let beta = 1.0lf / sqrt(sph[si + 14u]);
    var own_a = mat3x3<f64>();
    var own_b = mat3x3<f64>();
    var own_d = mat3x3<f64>();
    var coupling = array<f64, 6>();
    var contacts = 0u;
    for (var k = 0u; k < own_len + incoming; k++) {
        var q = row + k;
        if (k >= own_len) { q = u32(ints[inc0 + k - own_len]); }
        if (pf[touch_at(q)] == 0.0lf) { continue; }
        var a = i;
        if (k >= own_len) { a = first_sphere_of(first, count, q); }
        let b = u32(row_partner(q));
        let sa = sph_base(first, a);
        let sb = sph_base(first, b);
        let xa = load3(sa);
        let xb = load3(sb);
        let shift = image(row_shift(q));
        let l = (xb + shift) - xa;
        let distance = sqrt(sdot(l, l));
        if (!(distance > 0.0lf)) { continue; }
        let n = l / distance;
        let ra = sph[sa + 12u];
        let overlap = ra + sph[sb + 12u] - distance;
        let stiffness = contact_stiffness(ra, sph[sb + 12u], overlap);
        if (!(stiffness.x > 0.0lf)) { continue; }
        let kt = max(stiffness.y, 0.0lf);
        let spring = mat3x3<f64>(
            vec3<f64>(kt, 0.0lf, 0.0lf) + (stiffness.x - kt) * n.x * n,
            vec3<f64>(0.0lf, kt, 0.0lf) + (stiffness.x - kt) * n.y * n,
            vec3<f64>(0.0lf, 0.0lf, kt) + (stiffness.x - kt) * n.z * n);
        // The contact point in the middle of the overlap, seen from each centre.
        let point = xa + n * (ra - 0.5lf * overlap);
        var arm = point - xa;
        var other_arm = (point - shift) - xb;
        var other = sb;
        // A pair of a sphere with its own image comes twice (its row, its incoming list): first
        // as the pair's first sphere, then as its second.
        if (k >= own_len) { arm = other_arm; other_arm = point - xa; other = sa; }
        let alpha_o = 1.0lf / sqrt(sph[other + 13u]);
        let beta_o = 1.0lf / sqrt(sph[other + 14u]);
        let ks = times_skew(spring, arm);
        own_a += (alpha * alpha) * spring;
        own_b -= (alpha * beta) * ks;
        own_d -= (beta * beta) * skew_times(arm, ks);
        let ks_o = times_skew(spring, other_arm);
        let sk = skew_times(arm, spring);
        let sks_o = skew_times(arm, ks_o);
        for (var r = 0u; r < 3u; r++) {
            coupling[r] += alpha * alpha_o * row_abs(spring, r) + alpha * beta_o * row_abs(ks_o, r);
            coupling[r + 3u] += beta * alpha_o * row_abs(sk, r) + beta * beta_o * row_abs(sks_o, r);
        }
        contacts++;
    }
    if (contacts == 0u) { return vec2<f64>(-1.0lf, 0.0lf); }
    var bound = 0.0lf;
    for (var r = 0u; r < 3u; r++) {
        bound = max(bound, row_abs(own_a, r) + row_abs(own_b, r) + coupling[r]);
        bound = max(bound, col_abs(own_b, r) + row_abs(own_d, r) + coupling[r + 3u]);
    }
    return vec2<f64>(bound, f64(contacts));
}

fn round_away(x: f64) -> f64 {
    return sign(x) * floor(abs(x) + 0.5lf);
}

// Kraynik-Reinelt flip of the cell (`PeriodicCell::flip_if_needed`) by thread 0: sets w_minv to
// M^-1 (h_new = h_old M) and returns whether the cell flipped.
fn flip_if_needed() -> bool {
    var m = array<i32, 9>(1, 0, 0, 0, 1, 0, 0, 0, 1);
    var changed = false;
    for (var j = 0u; j < 3u; j++) {
        for (var i = 0u; i < 3u; i++) {
            if (i == j) { continue; }
            let ai = vec3<f64>(w_h[i], w_h[3u + i], w_h[6u + i]);
            let aj = vec3<f64>(w_h[j], w_h[3u + j], w_h[6u + j]);
            let k = round_away(sdot(aj, ai) / sdot(ai, ai));
            if (k != 0.0lf) {
                let nj = aj - ai * k;
                w_h[j] = nj.x; w_h[3u + j] = nj.y; w_h[6u + j] = nj.z;
                for (var q = 0u; q < 3u; q++) { m[3u * q + j] -= i32(k) * m[3u * q + i]; }
                changed = true;
            }
        }
    }
    if (changed) {
        // M is unimodular: its inverse is its adjugate over a determinant of +-1.
        let det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
        w_minv = array<i32, 9>(
            (m[4] * m[8] - m[5] * m[7]) * det, (m[2] * m[7] - m[1] * m[8]) * det, (m[1] * m[5] - m[2] * m[4]) * det,
            (m[5] * m[6] - m[3] * m[8]) * det, (m[0] * m[8] - m[2] * m[6]) * det, (m[2] * m[3] - m[0] * m[5]) * det,
            (m[3] * m[7] - m[4] * m[6]) * det, (m[1] * m[6] - m[0] * m[7]) * det, (m[0] * m[4] - m[1] * m[3]) * det);
    }
    return changed;
}

@compute @workgroup_size(WG)
fn run_rves(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    // Workgroups start in index order as the GPU's cores free up: the RVEs with the most steps
    // go first, and the short ones fill in behind them.
    for (var q = 0u; q < N_CONSTS; q++) { pc[q] = consts[q]; pu[q] = u32(max(consts[q], 0.0lf)); }
    let r = u32(rve[group.x * RVE_STRIDE + R_QUEUE]);
    let base = r * RVE_STRIDE;
    let first = u32(rve[base + R_FIRST]);
    let count = u32(rve[base + R_COUNT]);
    pair_first = u32(rve[base + R_PAIR_FIRST]);
    half = u32(rve[base + R_HALF]);
    cell_update = u32(rve[base + R_UPDATE]);
    let skin = cf(C_SKIN);
    if (lid == 0u) {
        for (var q = 0u; q < 9u; q++) { w_h[q] = rve[base + R_H + q]; w_l[q] = rve[base + R_L + q]; }
        let last = rve[base + R_LAST_DT];
        let total = u32(rve[base + R_STEPS]) + select(0u, 1u, last > 0.0lf);
        // A call's steps may take several dispatches: each goes on where the last one stopped.
        w_done = u32(rve[base + R_TAKEN]);
        w_steps = min(total, w_done + cu(C_CHUNK));
        if (rve[base + R_ERROR] != 0.0lf) { w_steps = w_done; }
        w_fail = 0u;
    }
    let done = workgroupUniformLoad(&w_done);
    let steps = workgroupUniformLoad(&w_steps);
    var rebuilds_here = 0u;
    for (var step = done; step < steps; step++) {
        if (lid == 0u) {
            w_rebuild = u32(rve[base + R_REBUILD]) | cu(C_FORCE_REBUILD);
            w_dt = rve[base + R_DT];
            if (step == u32(rve[base + R_STEPS])) { w_dt = rve[base + R_LAST_DT]; }
        }
        if (workgroupUniformLoad(&w_rebuild) != 0u) {
            // A software adapter's loop budget (see `Gpu::chunk`) holds few rebuilds: the rest
            // of the call's steps wait for the next dispatch.
            if (cu(C_REBUILDS) > 0u && rebuilds_here >= cu(C_REBUILDS)) { break; }
            rebuilds_here++;
            rebuild(r, lid, first, count);
            if (workgroupUniformLoad(&w_fail) != 0u) { break; }
        }
        if (lid == 0u) {
            // The time step is checked at the first step, then at a rebuild CHECK_EVERY steps
            // or more after the last check (`TimeStepCheck::due`).
            let last = rve[base + R_DT_LAST];
            let due = last < 0.0lf || (w_rebuild != 0u && rve[base + R_STEP] >= last + CHECK_EVERY);
            w_check = select(0u, 1u, due);
            // The cell at the step's end, and F = h_end h_build^-1 for the spheres' reference.
            let dt = w_dt;
            for (var q = 0u; q < 9u; q++) { w_ldt[q] = w_l[q] * dt; }
            for (var a = 0u; a < 3u; a++) {
                for (var b = 0u; b < 3u; b++) {
                    let lh = w_l[3u * a] * w_h[b] + w_l[3u * a + 1u] * w_h[3u + b] + w_l[3u * a + 2u] * w_h[6u + b];
                    w_hn[3u * a + b] = w_h[3u * a + b] + lh * dt;
                }
            }
            var hb: array<f64, 9>;
            for (var q = 0u; q < 9u; q++) { hb[q] = rve[base + R_HB + q]; }
            let hbi = inverse3(hb);
            for (var a = 0u; a < 3u; a++) {
                for (var b = 0u; b < 3u; b++) {
                    w_f[3u * a + b] = w_hn[3u * a] * hbi[b] + w_hn[3u * a + 1u] * hbi[3u + b] + w_hn[3u * a + 2u] * hbi[6u + b];
                }
            }
        }
        workgroupBarrier();
        let dt = workgroupUniformLoad(&w_dt);
        for (var i = lid; i < count; i += WG) { contacts_of(first, i, dt); }
        barrier_all();
        if (workgroupUniformLoad(&w_check) != 0u) {
            // The largest row's bound, the lowest sphere first among equals (the CPU's order).
            var best = -1.0lf;
            var best_i = 0u;
            var best_contacts = 0u;
            for (var i = lid; i < count; i += WG) {
                let g = stiffness_row(first, count, i);
                if (g.x > best) { best = g.x; best_i = i; best_contacts = u32(g.y); }
            }
            w_moved[lid] = best;
            w_bad[lid] = best_i;
            w_scan[lid] = best_contacts;
            workgroupBarrier();
            for (var h = WG / 2u; h > 0u; h = h / 2u) {
                if (lid < h) {
                    let o = lid + h;
                    if (w_moved[o] > w_moved[lid] || (w_moved[o] == w_moved[lid] && w_bad[o] < w_bad[lid])) {
                        w_moved[lid] = w_moved[o]; w_bad[lid] = w_bad[o]; w_scan[lid] = w_scan[o];
                    }
                }
                workgroupBarrier();
            }
            if (lid == 0u) {
                let step_now = rve[base + R_STEP];
                rve[base + R_DT_LAST] = step_now;
                let bound = w_moved[0];
                if (bound >= 0.0lf) {
                    let limit = 2.0lf / sqrt(bound * (1.0lf + max(cf(C_DAMPING), 0.0lf)));
                    if (rve[base + R_DT] > limit && rve[base + R_DT_LIMIT] == 0.0lf) {
                        rve[base + R_DT_LIMIT] = limit;
                        rve[base + R_DT_STEP] = step_now;
                        rve[base + R_DT_TIME] = rve[base + R_TIME];
                        rve[base + R_DT_SPHERE] = f64(w_bad[0]);
                        rve[base + R_DT_CONTACTS] = f64(w_scan[0]);
                        rve[base + R_DT_SAY] = 1.0lf - rve[base + R_DT_WARNED];
                        rve[base + R_DT_WARNED] = 1.0lf;
                    }
                }
            }
            workgroupBarrier();
        }
        var worst = 0.0lf;
        var bad = 0u;
        for (var i = lid; i < count; i += WG) {
            let m2 = move_sphere(first, i, dt);
            if (m2 < 0.0lf) { bad = 1u; } else if (m2 > worst) { worst = m2; }
        }
        w_moved[lid] = worst;
        w_bad[lid] = bad;
        barrier_all();
        // The largest displacement by halving (a maximum does not depend on its order).
        for (var half = WG / 2u; half > 0u; half = half / 2u) {
            if (lid < half) {
                w_moved[lid] = max(w_moved[lid], w_moved[lid + half]);
                w_bad[lid] = w_bad[lid] | w_bad[lid + half];
            }
            workgroupBarrier();
        }
        if (lid == 0u) {
            let moved2 = w_moved[0];
            let any_bad = w_bad[0];
            let moved = sqrt(moved2);
            w_h = w_hn;
            rve[base + R_TIME] += dt;
            rve[base + R_STEP] += 1.0lf;
            rve[base + R_TAKEN] += 1.0lf;
            let rmax = rve[base + R_RMAX];
            if (any_bad != 0u) {
                fail(r, FAIL_NOT_FINITE, 0.0lf);
            } else if (moved > 0.5lf * skin + rve[base + R_RMIN]) {
                fail(r, FAIL_TOO_FAST, moved);
            }
            w_flip = 0u;
            if (flip_if_needed()) {
                w_flip = 1u;
                rve[base + R_FLIPS] += 1.0lf;
                rve[base + R_REBUILD] = 1.0lf;
            }
            var growth2 = 0.0lf;
            for (var a = 0u; a < 3u; a++) {
                for (var b = 0u; b < 3u; b++) {
                    let e = w_f[3u * a + b] - select(0.0lf, 1.0lf, a == b);
                    growth2 += e * e;
                }
            }
            if (2.0lf * moved + sqrt(growth2) * (2.0lf * rmax + skin) > skin) { rve[base + R_REBUILD] = 1.0lf; }
        }
        if (workgroupUniformLoad(&w_flip) != 0u) {
            for (var i = lid; i < count; i += WG) {
                let row = u32(ints[cnt_base(first, i) + 5u]);
                for (var q = row; q < row + u32(ints[cnt_base(first, i)]); q++) {
                    let p = entry_at(half, q);
                    let n = vec3<i32>(ints[p + 1u], ints[p + 2u], ints[p + 3u]);
                    ints[p + 1u] = w_minv[0] * n.x + w_minv[1] * n.y + w_minv[2] * n.z;
                    ints[p + 2u] = w_minv[3] * n.x + w_minv[4] * n.y + w_minv[5] * n.z;
                    ints[p + 3u] = w_minv[6] * n.x + w_minv[7] * n.y + w_minv[8] * n.z;
                }
            }
            barrier_all();
        }
        if (workgroupUniformLoad(&w_fail) != 0u) { break; }
    }
    // The RVE's measures after the call: contact counts (integers, in any order), and the
    // Love-Weber stress (eq. 4.7) summed in the CPU engine's order (`DemWorld::
    // stress_and_axis_stiffness`): STRESS_LANES runs of consecutive pairs, each from zero, then
    // the runs' sums added pairwise in a fixed tree.
    barrier_all();
    if (lid == 0u) {
        atomicStore(&w_totals[0], 0u); atomicStore(&w_totals[1], 0u);
        atomicStore(&w_totals[2], 0u); atomicStore(&w_totals[3], 0u);
    }
    var counts = vec4<u32>(0u);
    let per = (count + WG - 1u) / WG;
    let lo = min(lid * per, count);
    let hi = min(lo + per, count);
    for (var i = lo; i < hi; i++) {
        let c = cnt_base(first, i);
        var mine = 0u;
        let row = u32(ints[c + 5u]);
        for (var q = row; q < row + u32(ints[c]); q++) {
            if (pf[touch_at(q)] != 0.0lf) { mine++; }
        }
        counts.x += mine;
        let base_in = incoming_at(u32(ints[c + 7u]));
        for (var k = 0u; k < u32(ints[c + 1u]); k++) {
            if (pf[touch_at(u32(ints[base_in + k]))] != 0.0lf) { mine++; }
        }
        counts.y += mine;
        if (mine == 1u) { counts.z += 1u; }
        if (mine == 0u) { counts.w += 1u; }
    }
    workgroupBarrier();
    atomicAdd(&w_totals[0], counts.x); atomicAdd(&w_totals[1], counts.y);
    atomicAdd(&w_totals[2], counts.z); atomicAdd(&w_totals[3], counts.w);
    let pairs = u32(rve[base + R_PAIRS]);
    let lane_pairs = max((pairs + STRESS_LANES - 1u) / STRESS_LANES, 1u);
    var sums: array<f64, 9u * LANES_EACH>;
    for (var u = 0u; u < LANES_EACH; u++) {
        // Workgroups wider than the runs leave their last invocations out.
        if (lid + u * WG >= STRESS_LANES) { continue; }
        let start = min((lid + u * WG) * lane_pairs, pairs);
        let end = min(start + lane_pairs, pairs);
        if (start >= end) { continue; }
        var a = first_sphere_of(first, count, start);
        var at = start;
        while (at < end) {
            let c = cnt_base(first, a);
            let row_start = u32(ints[c + 5u]);
            if (at >= row_start + u32(ints[c])) { a++; continue; }
            if (pf[touch_at(at)] != 0.0lf) {
                let f = pf3(force_at(at) + PF_FORCE);
                let l = (load3(sph_base(first, u32(row_partner(at)))) + image(row_shift(at))) - load3(sph_base(first, a));
                for (var i = 0u; i < 3u; i++) {
                    for (var j = 0u; j < 3u; j++) { sums[9u * u + 3u * i + j] += f[i] * l[j]; }
                }
            }
            at++;
        }
    }
    var s: array<f64, 9>;
    for (var q = 0u; q < 9u; q++) {
        for (var u = 0u; u < LANES_EACH; u++) {
            if (lid + u * WG < STRESS_LANES) { w_tree[lid + u * WG] = sums[9u * u + q]; }
        }
        workgroupBarrier();
        for (var half = STRESS_LANES / 2u; half > 0u; half = half / 2u) {
            for (var u = 0u; u < LANES_EACH; u++) {
                let t = lid + u * WG;
                if (t < half) { w_tree[t] += w_tree[t + half]; }
            }
            workgroupBarrier();
        }
        s[q] = w_tree[0];
        workgroupBarrier();
    }
    if (lid == 0u) {
        for (var q = 0u; q < 9u; q++) { rve[base + R_H + q] = w_h[q]; }
        let volume = abs(w_h[0] * (w_h[4] * w_h[8] - w_h[5] * w_h[7]) - w_h[1] * (w_h[3] * w_h[8] - w_h[5] * w_h[6])
            + w_h[2] * (w_h[3] * w_h[7] - w_h[4] * w_h[6]));
        rve[base + R_STRESS] = s[0] / volume;
        rve[base + R_STRESS + 1u] = s[4] / volume;
        rve[base + R_STRESS + 2u] = s[8] / volume;
        rve[base + R_STRESS + 3u] = 0.5lf * (s[1] + s[3]) / volume;
        rve[base + R_STRESS + 4u] = 0.5lf * (s[5] + s[7]) / volume;
        rve[base + R_STRESS + 5u] = 0.5lf * (s[2] + s[6]) / volume;
        rve[base + R_CONTACTS] = f64(atomicLoad(&w_totals[0]));
        rve[base + R_ENDS] = f64(atomicLoad(&w_totals[1]));
        rve[base + R_RATTLERS] = f64(atomicLoad(&w_totals[2]));
        rve[base + R_FLOATERS] = f64(atomicLoad(&w_totals[3]));
    }
}
