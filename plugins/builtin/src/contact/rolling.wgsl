// `rolling_resistance` on a device (rolling.rs, `DeviceLaw`): constants young, alpha_s, alpha_r,
// alpha_t, eta_r and the friction coefficient. The same operations as `init_pair` and the
// law's contact: the tangential spring-slider, then rolling and twisting springs capped at
// eta_r |F_n| min(r1, r2).
fn contact_stiffness(ra: f64, rb: f64, overlap: f64) -> vec2<f64> {
    let kn = 2.0lf * law_constant(0u) * ra * rb / (ra + rb);
    return vec2<f64>(kn, law_constant(1u) * kn);
}

fn contact_law(h: u32, ra: f64, rb: f64, n: vec3<f64>, overlap: f64, rel_v: vec3<f64>, spin: vec3<f64>, dt: f64) -> Law {
    let k = contact_stiffness(ra, rb, overlap);
    let kn = k.x;
    let kt = k.y;
    let fn_ = kn * overlap;
    var out: Law;
    out.force = spring_slider(h, n, rel_v, kt, law_constant(5u) * fn_, dt) - fn_ * n;
    let kr = law_constant(2u) * kt * ra * rb;
    let ktw = law_constant(3u) * kt * ra * rb;
    let limit = law_constant(4u) * min(ra, rb) * fn_;
    let s_n = sdot(spin, n);
    let roll = spin - s_n * n;
    var theta = rotate_into_plane(vec3<f64>(pf[h + 3u], pf[h + 4u], pf[h + 5u]), n) + roll * dt;
    var m_roll = kr * theta;
    let rs = beyond_scale(m_roll, limit);
    if (rs >= 0.0lf) { m_roll = m_roll * rs; theta = theta * rs; }
    var twist = pf[h + 6u] + s_n * dt;
    var m_twist = ktw * twist;
    let ts = beyond_scale(vec3<f64>(m_twist, 0.0lf, 0.0lf), limit);
    if (ts >= 0.0lf) { m_twist = m_twist * ts; twist = twist * ts; }
    pf[h + 3u] = theta.x; pf[h + 4u] = theta.y; pf[h + 5u] = theta.z; pf[h + 6u] = twist;
    out.moment = m_roll + m_twist * n;
    return out;
}
