// `linear` on a device (linear.rs, `DeviceLaw`): constants young (0: none), kn, kt_ratio, kt (-1:
// none) and the friction coefficient. The same operations as `Springs::of` and `Physics::contact`.
fn contact_stiffness(ra: f64, rb: f64, overlap: f64) -> vec2<f64> {
    var kn = law_constant(1u);
    if (law_constant(0u) > 0.0lf) { kn = 2.0lf * law_constant(0u) * ra * rb / (ra + rb); }
    var kt = law_constant(2u) * kn;
    if (law_constant(3u) >= 0.0lf) { kt = law_constant(3u); }
    return vec2<f64>(kn, kt);
}

fn contact_law(h: u32, ra: f64, rb: f64, n: vec3<f64>, overlap: f64, rel_v: vec3<f64>, spin: vec3<f64>, dt: f64) -> Law {
    let k = contact_stiffness(ra, rb, overlap);
    let fn_ = k.x * overlap;
    var out: Law;
    out.force = spring_slider(h, n, rel_v, k.y, law_constant(4u) * fn_, dt) - fn_ * n;
    out.moment = vec3<f64>(0.0lf);
    return out;
}
