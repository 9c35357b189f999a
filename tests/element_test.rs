//! Element tests from scripts (`element_test`): one material point along a strain or mixed path,
//! no mesh, against closed-form answers.

use granite_script::{run_source, RunOptions, RunReport};

use crate::common;

fn run(name: &str, source: &str) -> RunReport {
    let options = RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
    run_source(&format!("{name}.rhai"), source, granite::registry(), options).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn number(report: &RunReport, key: &str) -> f64 {
    common::summary_f64(report, key)
}

/// Drained triaxial compression of Mohr-Coulomb from an isotropic stress sigma3, the lateral
/// stresses held: q grows as E times the axial strain while elastic, and stops at the failure
/// deviator q_f = sigma3 (Kp - 1) + 2 c sqrt(Kp), Kp = (1 + sin phi)/(1 - sin phi) (compression
/// magnitudes). The driver holds the lateral stresses to 1e-7 of the stress, the law returns to
/// its surface to about 1e-8: 1e-6 on q_f.
#[test]
fn mohr_coulomb_triaxial_reaches_its_failure_deviator() {
    for (phi, cohesion, sigma3) in [(30.0, 0.0, 1e5), (40.0, 0.0, 2e5), (30.0, 1e4, 1e5)] {
        let young = 2e7;
        let source = format!(
            r#"
let s3 = -{sigma3:?};
let r = element_test("mohr_coulomb", #{{ young: {young:?}, poisson: 0.3, friction: {phi:?}, cohesion: {cohesion:?} }}, #{{
    stress: [s3, s3, s3, 0.0, 0.0, 0.0], strain: [0.0, 0.0, -0.05, 0.0, 0.0, 0.0],
    hold: #{{ xx: s3, yy: s3 }}, steps: 1000 }});
let last = r.q.len() - 1;
summary("q_final", r.q[last]);
summary("q_early", r.q[5]);
summary("axial_early", -r.strain[5][2]);
summary("lateral_final", r.stress[last][0]);
summary("pdstrain_final", r.state.pdstrain[last]);
summary("pdstrain_early", r.state.pdstrain[5]);
"#
        );
        let s = run(&format!("element_mc_{phi}_{cohesion}"), &source);
        let sin = f64::to_radians(phi).sin();
        let kp = (1.0 + sin) / (1.0 - sin);
        let q_f = sigma3 * (kp - 1.0) + 2.0 * cohesion * kp.sqrt();
        let q = number(&s, "q_final");
        assert!((q - q_f).abs() < 1e-6 * q_f, "phi {phi}, c {cohesion}: q_f = {q}, expected {q_f}");
        // Elastic at first, at constant lateral stress: q = E eps_axial.
        let (q0, e0) = (number(&s, "q_early"), number(&s, "axial_early"));
        assert!((q0 - young * e0).abs() < 1e-6 * q0, "elastic q = {q0}, E eps = {}", young * e0);
        assert!((number(&s, "lateral_final") + sigma3).abs() < 1e-6 * sigma3);
        assert_eq!(number(&s, "pdstrain_early"), 0.0);
        assert!(number(&s, "pdstrain_final") > 0.0);
    }
}

/// Linear elasticity under a strain path of uniaxial (oedometric) compression:
/// sigma_zz = (lambda + 2G) eps, sigma_xx = sigma_yy = lambda eps.
#[test]
fn linear_elastic_oedometer() {
    let source = r#"
let r = element_test("linear_elastic", #{ young: 1e7, poisson: 0.25 }, #{ strain: [0.0, 0.0, -0.001, 0.0, 0.0, 0.0], steps: 10 });
summary("szz", r.stress[10][2]);
summary("sxx", r.stress[10][0]);
summary("p", r.p[10]);
"#;
    let s = run("element_oedometer", source);
    let (e, nu, eps) = (1e7, 0.25, -0.001);
    let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let g = e / (2.0 * (1.0 + nu));
    assert!((number(&s, "szz") - (lambda + 2.0 * g) * eps).abs() < 1e-9 * e);
    assert!((number(&s, "sxx") - lambda * eps).abs() < 1e-9 * e);
    // p is the mean pressure, compression positive.
    assert!((number(&s, "p") + (3.0 * lambda + 2.0 * g) * eps / 3.0).abs() < 1e-9 * e);
}

/// `dem_rve` on one point: a simple cubic lattice RVE (spheres of 1 mm just touching, k_n =
/// 1e5 N/m) compressed isotropically by eps = 1e-4 carries the Love-Weber stress of its contacts,
/// -k_n delta / d^2 with delta = d eps the overlap and d = 2 r: -k_n eps / (2 r) = -5 kPa. The
/// lattice deforms affinely (each sphere balanced by symmetry). The stress an RVE returns is that
/// of its last DEM step's forces, computed before that step's deformation: with 50 DEM steps per
/// call and 10 calls, at the strain eps (1 - 1/500). A mixed path is refused for a law with an
/// object per point.
#[test]
fn dem_rve_lattice_under_isotropic_compression() {
    let (kn, radius, eps, dem_steps, calls) = (1e5, 1e-3, 1e-4, 50, 10);
    let source = format!(
        r#"
let rve = dem(#{{ skin: 1e-4 }});
let g = rve.material(#{{ density: 2650.0 }});
rve.contact_law("linear", #{{ kn: {kn:?} }});
let r = {radius:?};
rve.periodic([8.0 * r, 8.0 * r, 8.0 * r]);
for i in 0..4 {{ for j in 0..4 {{ for k in 0..4 {{
    rve.sphere(g, [(2 * i + 1).to_float() * r, (2 * j + 1).to_float() * r, (2 * k + 1).to_float() * r], r);
}} }} }}
rve.dt(5e-6);
let t = element_test("dem_rve", #{{ rve: rve, dem_steps: {dem_steps} }}, #{{ strain: [-{eps:?}, -{eps:?}, -{eps:?}, 0.0, 0.0, 0.0], steps: {calls} }});
summary("sxx", t.stress[{calls}][0]);
summary("szz", t.stress[{calls}][2]);
summary("sxy", t.stress[{calls}][3]);
let refused = "";
try {{
    element_test("dem_rve", #{{ rve: rve }}, #{{ strain: [0.0, 0.0, -1e-4, 0.0, 0.0, 0.0], hold: #{{ xx: -5e3 }}, steps: 2 }});
}} catch (e) {{ refused = e; }}
summary("refused", refused);
"#
    );
    let s = run("element_dem_rve", &source);
    // The forces of the last DEM step: one DEM step of strain short of the whole path.
    let expected = -kn * eps * (1.0 - 1.0 / (dem_steps * calls) as f64) / (2.0 * radius);
    for key in ["sxx", "szz"] {
        assert!((number(&s, key) - expected).abs() < 1e-3 * expected.abs(), "{key} = {}", number(&s, key));
    }
    assert!(number(&s, "sxy").abs() < 1e-6 * expected.abs());
    let refused = s.summary.get("refused").and_then(|v| v.as_str()).unwrap_or_default().to_string();
    assert!(refused.contains("strain path only"), "{refused}");
}
