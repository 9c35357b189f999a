//! Chung & Ooi (2011), "Benchmark tests for verifying discrete element modelling codes at particle
//! impact level", Granular Matter 13:643-656: tests 1 to 3, written with the script API alone (the
//! way a user checks a code), each against Hertz's theory of elastic impact.
//!
//! Hertz, for two bodies meeting at relative speed v (m* = m1 m2/(m1 + m2), R* = R1 R2/(R1 + R2),
//! 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2, a rigid plane adding no compliance and R* = R):
//! - largest overlap d_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5);
//! - largest force F_max = 4/3 E* sqrt(R*) d_max^(3/2);
//! - contact duration t_c = 2 (d_max / v) I, I = integral from 0 to 1 of dx / sqrt(1 - x^(5/2)).
//!
//! The time step is 1 % of the Rayleigh time step `pi R sqrt(rho/G) / (0.1631 nu + 0.8766)`, as in
//! the benchmark's reference runs; the contact then lasts about 300 steps, so the duration counted
//! in steps is within 1 % and the sampled extremes closer still: hence 1 % on all three.

use granite_script::{run_source, RunOptions, RunReport};

use crate::common;

struct Material {
    name: &'static str,
    young: f64,
    poisson: f64,
    density: f64,
}

/// Test 1's materials.
const GLASS: Material = Material { name: "glass", young: 4.8e10, poisson: 0.20, density: 2800.0 };
const LIMESTONE: Material = Material { name: "limestone", young: 2.0e10, poisson: 0.25, density: 2500.0 };
/// Test 2's.
const ALUMINIUM_ALLOY: Material = Material { name: "aluminium_alloy", young: 7.0e10, poisson: 0.30, density: 2699.0 };
const MAGNESIUM_ALLOY: Material = Material { name: "magnesium_alloy", young: 4.0e10, poisson: 0.35, density: 1800.0 };
/// Test 3's.
const ALUMINIUM_OXIDE: Material = Material { name: "aluminium_oxide", young: 3.8e11, poisson: 0.23, density: 4000.0 };
const CAST_IRON: Material = Material { name: "cast_iron", young: 1.0e11, poisson: 0.25, density: 7000.0 };

/// The script's part shared by the tests: a material, the law, the time step, and a loop that steps
/// until the contact named by `contact` has come and gone, recording its extremes.
fn impact_script(m: &Material, radius: f64, law: &str, set_up: &str, contact: &str) -> String {
    format!(
        r#"
let sim = dem();
let grain = sim.material(#{{ name: "{name}", density: {rho:?}, young: {e:?}, poisson: {nu:?} }});
let rigid = sim.material(#{{ name: "rigid", density: {rho:?}, rigid: true }});
sim.contact_law("hertz_mindlin", #{{ {law} }});
let r = {radius:?};
{set_up}
let shear = {e:?} / (2.0 * (1.0 + {nu:?}));
let rayleigh = PI() * r * sqrt({rho:?} / shear) / (0.1631 * {nu:?} + 0.8766);
sim.dt(0.01 * rayleigh);
sim.series_every(1000000);
let max_force = 0.0;
let max_overlap = 0.0;
let steps_in_contact = 0;
let started = false;
for k in 0..1000000 {{
    sim.step();
    let c = {contact};
    if c == () {{
        if started {{ break; }}
        continue;
    }}
    started = true;
    steps_in_contact += 1;
    if c.normal_force > max_force {{ max_force = c.normal_force; }}
    if c.overlap > max_overlap {{ max_overlap = c.overlap; }}
}}
summary("max_force", max_force);
summary("max_overlap", max_overlap);
summary("duration", steps_in_contact.to_float() * sim.dt);
summary("velocity_after", sim.body(0).velocity[0]);
"#,
        name = m.name,
        rho = m.density,
        e = m.young,
        nu = m.poisson,
    )
}

fn run(name: &str, source: &str) -> RunReport {
    let options = RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
    run_source(&format!("{name}.rhai"), source, granite::registry(), options).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn number(report: &RunReport, key: &str) -> f64 {
    common::summary_f64(report, key)
}

/// `integral_0^1 dx / sqrt(1 - x^(5/2))`, with x = 1 - u^2 to take the root singularity away.
fn duration_integral() -> f64 {
    let n = 200_000;
    let h = 1.0 / n as f64;
    (0..n)
        .map(|k| {
            let u = (k as f64 + 0.5) * h;
            let x: f64 = 1.0 - u * u;
            2.0 * u / (1.0 - x.powf(2.5)).sqrt() * h
        })
        .sum()
}

struct Hertz {
    max_overlap: f64,
    max_force: f64,
    duration: f64,
}

fn hertz(e_star: f64, r_star: f64, m_star: f64, v: f64) -> Hertz {
    let max_overlap = (15.0 * m_star * v * v / (16.0 * e_star * r_star.sqrt())).powf(0.4);
    Hertz {
        max_overlap,
        max_force: 4.0 / 3.0 * e_star * r_star.sqrt() * max_overlap.powf(1.5),
        duration: 2.0 * max_overlap / v * duration_integral(),
    }
}

fn mass(m: &Material, r: f64) -> f64 {
    m.density * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3)
}

fn assert_close(what: &str, got: f64, expected: f64, tolerance: f64) {
    let rel = (got - expected).abs() / expected;
    assert!(rel < tolerance, "{what}: {got:e}, Hertz {expected:e} ({:.3} % off)", 100.0 * rel);
}

#[test]
fn duration_integral_is_the_known_constant() {
    // 2 I = 2.9432 (Johnson, Contact Mechanics, eq. 11.24).
    assert!((2.0 * duration_integral() - 2.9432).abs() < 1e-4);
}

/// Test 1: two identical spheres (R = 10 mm) meeting head-on at 10 m/s each.
#[test]
fn test1_elastic_normal_impact_of_two_identical_spheres() {
    for m in [GLASS, LIMESTONE] {
        let (r, v) = (0.010, 10.0);
        let set_up = format!(
            "sim.sphere(grain, [-r - 1e-6, 0.0, 0.0], r, #{{ velocity: [{v:?}, 0.0, 0.0] }});
             sim.sphere(grain, [r + 1e-6, 0.0, 0.0], r, #{{ velocity: [-{v:?}, 0.0, 0.0] }});"
        );
        let source = impact_script(&m, r, "friction: 19.29", &set_up, "sim.contact(0, 1)");
        let s = run(&format!("chung_ooi_1_{}", m.name), &source);
        let e_star = m.young / (2.0 * (1.0 - m.poisson * m.poisson));
        let expected = hertz(e_star, r / 2.0, mass(&m, r) / 2.0, 2.0 * v);
        assert_close(&format!("{} max overlap", m.name), number(&s, "max_overlap"), expected.max_overlap, 0.01);
        assert_close(&format!("{} max force", m.name), number(&s, "max_force"), expected.max_force, 0.01);
        assert_close(&format!("{} duration", m.name), number(&s, "duration"), expected.duration, 0.01);
        // Elastic: each sphere leaves with its speed.
        assert_close(&format!("{} rebound speed", m.name), -number(&s, "velocity_after"), v, 1e-3);
    }
}

/// Test 2: a sphere (R = 0.1 m) hitting a rigid plane at 0.2 m/s. The wall's material is rigid
/// (an infinite modulus), so E* is the sphere's E/(1 - nu^2), also when the law is given the
/// sphere's moduli as its own: a rigid body stays rigid.
#[test]
fn test2_elastic_normal_impact_of_a_sphere_with_a_rigid_plane() {
    for (m, own) in [(ALUMINIUM_ALLOY, false), (MAGNESIUM_ALLOY, false), (ALUMINIUM_ALLOY, true)] {
        let (r, v) = (0.10, 0.2);
        let set_up = format!(
            "sim.sphere(grain, [-r - 1e-6, 0.0, 0.0], r, #{{ velocity: [{v:?}, 0.0, 0.0] }});
             sim.wall_plane(rigid, [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]);"
        );
        let law = if own { format!("young: {:?}, poisson: {:?}", m.young, m.poisson) } else { String::new() };
        let source = impact_script(&m, r, &law, &set_up, "sim.wall_contact(0, 0)");
        let s = run(&format!("chung_ooi_2_{}_{own}", m.name), &source);
        let e_star = m.young / (1.0 - m.poisson * m.poisson);
        let expected = hertz(e_star, r, mass(&m, r), v);
        assert_close(&format!("{} max overlap", m.name), number(&s, "max_overlap"), expected.max_overlap, 0.01);
        assert_close(&format!("{} max force", m.name), number(&s, "max_force"), expected.max_force, 0.01);
        assert_close(&format!("{} duration", m.name), number(&s, "duration"), expected.duration, 0.01);
    }
}

/// Test 3: a sphere (R = 2.5 mm) hitting a rigid plane at 3.9 m/s with a damped Hertz contact; the
/// restitution measured from the rebound speed must be the one asked, within 0.01.
#[test]
fn test3_normal_contact_with_different_restitution_coefficients() {
    for m in [ALUMINIUM_OXIDE, CAST_IRON] {
        for e_in in [0.2, 0.4, 0.6, 0.8, 1.0] {
            let (r, v) = (0.0025, 3.9);
            let set_up = format!(
                "sim.sphere(grain, [-r - 1e-6, 0.0, 0.0], r, #{{ velocity: [{v:?}, 0.0, 0.0] }});
                 sim.wall_plane(rigid, [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]);"
            );
            let law = format!("restitution: {e_in:?}");
            let source = impact_script(&m, r, &law, &set_up, "sim.wall_contact(0, 0)");
            let s = run(&format!("chung_ooi_3_{}_{e_in}", m.name), &source);
            let e_out = -number(&s, "velocity_after") / v;
            assert!((e_out - e_in).abs() < 0.01, "{}: restitution {e_out} for e = {e_in}", m.name);
        }
    }
}
