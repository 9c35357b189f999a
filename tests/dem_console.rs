//! Single bodies and contacts of a DEM run, read and changed from scripts between steps: the
//! console a YADE user expects (`O.bodies`, `O.interactions`, `O.forces`), each call checked
//! against mechanics or against an uninterrupted run.

use granite_script::{run_source, RunOptions, RunReport};

use crate::common;

fn run(name: &str, source: &str) -> RunReport {
    let options = RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
    run_source(&format!("{name}.rhai"), source, granite::registry(), options).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn number(report: &RunReport, key: &str) -> f64 {
    common::summary_f64(report, key)
}

fn value<'a>(report: &'a RunReport, key: &str) -> &'a serde_json::Value {
    report.summary.get(key).unwrap_or_else(|| panic!("no `{key}` in the summary"))
}

/// A frictional packing of 120 spheres settled under gravity in a box (1 cm spheres, linear law,
/// E = 1e7 Pa, friction 30 degrees): the scene of the tests that change things mid-run.
const PACKING: &str = r#"
let r = 0.01;
let rho = 2600.0;
let sim = dem(#{ seed: 3, skin: 0.5 * r });
let glass = sim.material(#{ name: "glass", density: rho });
sim.contact_law("linear", #{ young: 1.0e7, kt_ratio: 0.3, friction: 30.0 });
sim.box_walls(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.3], #{ open_top: true });
sim.lattice(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.12], #{ spacing: 2.2 * r, radius: r, jitter: 0.1 * r });
sim.gravity([0.0, 0.0, -9.81]);
sim.damping(0.3);
sim.dt(0.3 * r * sqrt(rho / 1.0e7));
sim.series_every(1000000);
sim.run_steps(6000);
"#;

/// A constant external force and torque on a free sphere given a mass of its own, no gravity:
/// the leapfrog gives v = F t / m and w = T t / I exactly (to rounding), whatever the time step.
#[test]
fn an_external_load_accelerates_a_sphere_as_newton_says() {
    let source = r#"
let sim = dem();
let steel = sim.material(#{ density: 7800.0 });
sim.contact_law("linear", #{ kn: 1e6 });
let id = sim.sphere(steel, [0.0, 0.0, 0.0], 0.01);
sim.set_body(id, #{ force: [0.5, 0.0, -0.25], torque: [0.0, 1e-4, 0.0], mass: 2.0 });
sim.dt(1e-4);
sim.series_every(1000000);
sim.run_steps(1000);
let b = sim.body(id);
summary("vx", b.velocity[0]);
summary("vz", b.velocity[2]);
summary("wy", b.spin[1]);
summary("mass", b.mass);
summary("inertia", b.inertia);
summary("time", sim.time);
summary("external", b.external_force[0]);
"#;
    let s = run("console_external_load", source);
    let (m, i, t) = (number(&s, "mass"), number(&s, "inertia"), number(&s, "time"));
    // A mass of its own, the moment of inertia following.
    assert_eq!(m, 2.0);
    assert!((i - 0.4 * 2.0 * 0.01 * 0.01).abs() < 1e-15);
    assert!((number(&s, "vx") - 0.5 * t / m).abs() < 1e-9 * 0.5 * t / m);
    assert!((number(&s, "vz") + 0.25 * t / m).abs() < 1e-9 * 0.25 * t / m);
    assert!((number(&s, "wy") - 1e-4 * t / i).abs() < 1e-9 * 1e-4 * t / i);
    assert_eq!(number(&s, "external"), 0.5);
}

/// Degrees of freedom fixed by name keep their velocity under gravity; the others fall.
#[test]
fn fixed_degrees_of_freedom_keep_their_velocity() {
    let source = r#"
let sim = dem();
let m = sim.material(#{ density: 1000.0 });
sim.contact_law("linear", #{ kn: 1.0 });
let a = sim.sphere(m, [0.0, 0.0, 0.0], 0.01, #{ velocity: [0.0, 0.0, 0.3], fixed: "z" });
let b = sim.sphere(m, [1.0, 0.0, 0.0], 0.01);
sim.set_body(b, #{ fixed: "xy" });
sim.gravity([0.0, -2.0, -9.81]);
sim.dt(1e-3);
sim.series_every(1000000);
sim.run_steps(100);
summary("a_vz", sim.body(a).velocity[2]);
summary("a_vy", sim.body(a).velocity[1]);
summary("b_vy", sim.body(b).velocity[1]);
summary("b_vz", sim.body(b).velocity[2]);
summary("a_fixed", sim.body(a).fixed);
summary("time", sim.time);
"#;
    let s = run("console_fixed", source);
    let t = number(&s, "time");
    assert_eq!(number(&s, "a_vz"), 0.3);
    assert!((number(&s, "a_vy") + 2.0 * t).abs() < 1e-12);
    assert_eq!(number(&s, "b_vy"), 0.0);
    assert!((number(&s, "b_vz") + 9.81 * t).abs() < 1e-12);
    assert_eq!(value(&s, "a_fixed"), "z");
}

/// The forces of a sphere's contacts add up to its force (Newton's third law, each contact
/// counted from the sphere's side), and every listed contact overlaps and pushes.
#[test]
fn listed_contact_forces_add_up_to_each_sphere_force() {
    let source = format!(
        "{PACKING}
let ids = sim.ids();
let forces = sim.forces();
let sums = #{{}};
for id in ids {{ sums[id.to_string()] = [0.0, 0.0, 0.0]; }}
let worst = 0.0;
let pushing = true;
for c in sim.contacts() {{
    if c.normal_force <= 0.0 {{ pushing = false; }}
    let s1 = sums[c.id1.to_string()];
    for a in 0..3 {{ s1[a] += c.force[a]; }}
    sums[c.id1.to_string()] = s1;
    if c.contains(\"id2\") {{
        let s2 = sums[c.id2.to_string()];
        for a in 0..3 {{ s2[a] -= c.force[a]; }}
        sums[c.id2.to_string()] = s2;
    }}
}}
let largest = 0.0;
for k in 0..ids.len() {{
    let s = sums[ids[k].to_string()];
    for a in 0..3 {{
        let d = (s[a] - forces[k][a]).abs();
        if d > worst {{ worst = d; }}
        if forces[k][a].abs() > largest {{ largest = forces[k][a].abs(); }}
    }}
}}
summary(\"worst\", worst);
summary(\"largest\", largest);
summary(\"pushing\", pushing);
summary(\"contacts\", sim.contacts().len());
"
    );
    let s = run("console_contact_sums", &source);
    assert!(number(&s, "contacts") > 100.0);
    assert_eq!(value(&s, "pushing"), true);
    assert!(number(&s, "worst") <= 1e-12 * number(&s, "largest"), "worst {}", number(&s, "worst"));
}

/// A simple cubic lattice of touching spheres has contacts along the three axes in equal numbers:
/// the fabric tensor is one third of the identity.
#[test]
fn fabric_of_a_cubic_lattice_is_isotropic() {
    let source = r#"
let sim = dem();
let m = sim.material(#{ density: 1000.0 });
sim.contact_law("linear", #{ kn: 1e4 });
let r = 0.01;
sim.periodic([0.1, 0.1, 0.1]);
for i in 0..5 { for j in 0..5 { for k in 0..5 {
    let at = |n| (n.to_float() + 0.5) * 2.0 * r;
    sim.sphere(m, [at.call(i), at.call(j), at.call(k)], 1.001 * r);
} } }
sim.dt(1e-5);
sim.series_every(1000000);
sim.step();
summary("fabric", sim.fabric());
summary("contacts", sim.contacts().len());
summary("particles", sim.particles);
"#;
    let s = run("console_fabric", source);
    assert_eq!(number(&s, "contacts"), 3.0 * number(&s, "particles"));
    let f = value(&s, "fabric").as_array().unwrap();
    for (a, row) in f.iter().enumerate() {
        for (b, v) in row.as_array().unwrap().iter().enumerate() {
            let expected = if a == b { 1.0 / 3.0 } else { 0.0 };
            assert!((v.as_f64().unwrap() - expected).abs() < 1e-9, "F[{a}][{b}] = {v}");
        }
    }
}

/// Positions after `steps` more steps of the packing, with `change` made first (one line of
/// script); the summary holds them flat.
fn continued(name: &str, change: &str, steps: u64) -> (Vec<f64>, RunReport) {
    let source = format!(
        "{PACKING}
summary(\"unbalanced_before\", sim.diagnostics().unbalanced_force);
let shear_before = 0.0;
for c in sim.contacts() {{ shear_before += (c.shear_force[0] ** 2 + c.shear_force[1] ** 2 + c.shear_force[2] ** 2).sqrt(); }}
summary(\"shear_before\", shear_before);
{change}
sim.step();
summary(\"unbalanced_after\", sim.diagnostics().unbalanced_force);
let shear_after = 0.0;
let over_limit = 0;
let fastest = 0.0;
for v in sim.velocities() {{ fastest = max(fastest, (v[0] ** 2 + v[1] ** 2 + v[2] ** 2).sqrt()); }}
for c in sim.contacts() {{
    let ft = (c.shear_force[0] ** 2 + c.shear_force[1] ** 2 + c.shear_force[2] ** 2).sqrt();
    shear_after += ft;
    // The normal turned by at most 2 |v|max dt / r since the law split the force.
    let turn = 2.0 * fastest * sim.dt / r;
    if ft > c.params.mu * c.normal_force * (1.0 + turn * (1.0 + 1.0 / c.params.mu)) {{ over_limit += 1; }}
}}
summary(\"shear_after\", shear_after);
summary(\"over_limit\", over_limit);
sim.run_steps({steps});
let flat = [];
for x in sim.positions() {{ flat += x; }}
summary(\"positions\", flat);
"
    );
    let s = run(name, &source);
    let flat = value(&s, "positions").as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    (flat, s)
}

/// Setting a law's parameters to the values it has changes nothing: the run goes on bit for bit
/// (contacts and their tangential springs are kept; they were all dropped before).
#[test]
fn setting_the_same_contact_parameters_continues_bit_for_bit() {
    let (reference, _) = continued("console_params_none", "", 500);
    let (same, _) = continued("console_params_same", "sim.set_contact_params(#{ friction: 30.0 });", 500);
    let (again, _) = continued(
        "console_law_again",
        "sim.contact_law(\"linear\", #{ young: 1.0e7, kt_ratio: 0.3, friction: 30.0 });",
        500,
    );
    assert_eq!(reference, same);
    assert_eq!(reference, again);
}

/// Friction lowered from 30 to 20 degrees in a settled packing: every contact keeps its
/// tangential spring, capped by the new Coulomb limit at the next step. (A listed contact splits
/// the last step's force along the present normal, which has turned by up to 2 |v|max dt / r since
/// the law split it: the limit is checked with that margin.) The shear the packing
/// carries then stays within the new limits, close to what it was (a contact whose spring was
/// dropped would carry none after one step), and the unbalanced force does not jump.
#[test]
fn lowering_friction_mid_run_keeps_the_packing() {
    let (_, s) = continued("console_friction", "sim.set_contact_params(#{ friction: 20.0 });", 0);
    let (before, after) = (number(&s, "shear_before"), number(&s, "shear_after"));
    assert_eq!(number(&s, "over_limit"), 0.0);
    // The cap scales a spring by at most tan 20° / tan 30° = 0.63.
    let cap = 20f64.to_radians().tan() / 30f64.to_radians().tan();
    assert!(after >= cap * before * 0.99 && after <= before * 1.01, "shear {before} -> {after}");
    let (u0, u1) = (number(&s, "unbalanced_before"), number(&s, "unbalanced_after"));
    assert!(u1 < 2.0 * u0 + 0.01, "unbalanced force {u0} -> {u1}");
}

/// Erasing a sphere that touches nothing leaves the others' motion bit for bit: the remaining
/// contacts keep their history (erasing used to drop every contact).
#[test]
fn erasing_a_sphere_keeps_the_other_contacts() {
    let lone = "let lone = sim.sphere(glass, [0.05, 0.05, 0.28], 0.005, #{ fixed: true });";
    let keep = format!("{lone}\n");
    let erase = format!("{lone}\nsim.step(); sim.erase(lone);\n");
    let (kept, _) = continued("console_erase_kept", &format!("{keep}sim.step();"), 300);
    let (erased, _) = continued("console_erase_erased", &erase, 300);
    // The lone sphere is the last one: the others' positions come first.
    assert_eq!(kept.len(), erased.len() + 3);
    assert_eq!(&kept[..erased.len()], &erased[..]);
}

/// A material's moduli changed mid-run reach the contacts already made at the next step: the
/// Hertz pair values follow E* = E / (2 (1 - nu^2)) for two grains of the material.
#[test]
fn a_new_modulus_reaches_existing_hertz_contacts() {
    let source = r#"
let sim = dem();
let m = sim.material(#{ density: 2500.0, young: 1e8, poisson: 0.25 });
sim.contact_law("hertz_mindlin", #{ friction: 20.0 });
let a = sim.sphere(m, [0.0, 0.0, 0.0], 0.01, #{ fixed: true });
let b = sim.sphere(m, [0.0, 0.0, 0.0199], 0.01, #{ fixed: true });
sim.dt(1e-6);
sim.series_every(1000000);
sim.step();
summary("before", sim.contact(a, b).params.e_star);
sim.set_material(m, #{ young: 4e8, poisson: 0.3 });
sim.step();
summary("after", sim.contact(a, b).params.e_star);
summary("force_after", sim.contact(a, b).normal_force);
summary("overlap", sim.contact(a, b).overlap);
"#;
    let s = run("console_modulus", source);
    assert!((number(&s, "before") - 1e8 / (2.0 * (1.0 - 0.0625))).abs() < 1e-3);
    let e_star = 4e8 / (2.0 * (1.0 - 0.09));
    assert!((number(&s, "after") - e_star).abs() < 1e-3);
    let (delta, r_star) = (number(&s, "overlap"), 0.005f64);
    let hertz = 4.0 / 3.0 * e_star * r_star.sqrt() * delta.powf(1.5);
    assert!((number(&s, "force_after") - hertz).abs() < 1e-9 * hertz);
}

/// A DEM frame for ParaView: the spheres (ids as integers), the walls as polygons and the contact
/// network as one line per touching contact, binary by default, text when asked.
#[test]
fn vtk_frames_show_walls_and_force_chains() {
    let source = format!(
        "{PACKING}
sim.vtk_format(\"ascii\");
sim.step();
sim.write_vtk();
summary(\"contacts\", sim.contacts().len());
"
    );
    let s = run("console_vtk", &source);
    let vtk = s.out_dir.join("vtk");
    let last = |stem: &str, ext: &str| {
        let mut files: Vec<_> = std::fs::read_dir(&vtk)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with(stem) && p.extension().unwrap() == ext)
            .collect();
        files.sort();
        String::from_utf8_lossy(&std::fs::read(files.last().unwrap()).unwrap()).to_string()
    };
    let contacts = last("contacts_", "vtp");
    assert!(contacts.contains(&format!("NumberOfLines=\"{}\"", number(&s, "contacts"))), "{}", &contacts[..400]);
    assert!(contacts.contains("Name=\"normal_force\"") && contacts.contains("type=\"Int64\" Name=\"id1\""));
    // Five plane walls of the open box.
    assert!(last("walls_", "vtp").contains("NumberOfPolys=\"5\""));
    let points = last("points_", "vtu");
    assert!(points.contains("type=\"Int64\" Name=\"id\""));
    assert!(points.contains("format=\"ascii\""));
    // Frames written during the run, before `vtk_format`, are binary.
    let first = String::from_utf8_lossy(&std::fs::read(vtk.join("contacts_000000.vtp")).unwrap()).to_string();
    assert!(
        first.contains("compressor=\"vtkZLibDataCompressor\"") && first.contains("<AppendedData encoding=\"raw\">")
    );
    for series in ["points.pvd", "walls.pvd", "contacts.pvd"] {
        assert!(vtk.join(series).exists(), "{series}");
    }
}

/// Parameters changed for one material reach every pair that material is in, and no other.
#[test]
fn contact_parameters_change_per_material() {
    let source = r#"
let sim = dem();
let a = sim.material(#{ name: "a", density: 1000.0 });
let b = sim.material(#{ name: "b", density: 1000.0 });
sim.contact_law("linear", #{ kn: 1e4, kt_ratio: 0.5, friction: 30.0 });
sim.set_contact_params(a, #{ friction: 10.0 });
summary("aa", sim.contact_law_params(a, a).friction);
summary("ab", sim.contact_law_params(a, b).friction);
summary("bb", sim.contact_law_params(b, b).friction);
summary("kn", sim.contact_law_params(a, b).kn);
"#;
    let s = run("console_per_material", source);
    assert_eq!((number(&s, "aa"), number(&s, "ab"), number(&s, "bb")), (10.0, 10.0, 30.0));
    assert_eq!(number(&s, "kn"), 1e4);
}
