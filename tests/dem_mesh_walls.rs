//! Walls of triangles from STL files and gmsh surfaces (`sim.wall_mesh`): a sphere on them moves
//! as on the plane they lie in, a seam between two triangles is one contact, a shaken closed box
//! of triangles holds its spheres.

use crate::common;
use common::*;
use std::fmt::Write;

type Triangle = [[f64; 3]; 3];

fn write_stl(path: &std::path::Path, triangles: &[Triangle]) {
    let mut s = String::from("solid test\n");
    for t in triangles {
        s.push_str("facet normal 0 0 0\nouter loop\n");
        for v in t {
            // Rust prints the shortest text that reads back to the same number.
            writeln!(s, "vertex {:?} {:?} {:?}", v[0], v[1], v[2]).unwrap();
        }
        s.push_str("endloop\nendfacet\n");
    }
    s.push_str("endsolid test\n");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, s).unwrap();
}

#[test]
fn a_sphere_rolls_down_two_triangles_across_their_seam_as_down_their_plane() {
    // An incline at 20 degrees: two triangles sharing the seam y = 0 along the slope, which
    // the sphere rolls down on. Over a seam it must feel one contact, exactly the plane's.
    let theta = 20f64.to_radians();
    let t = [theta.cos(), 0.0, theta.sin()];
    let n = [-theta.sin(), 0.0, theta.cos()];
    let at = |s: f64, y: f64| [s * t[0], y, s * t[2]];
    let stl = root().join("target/test-out/mesh_wall_inputs/incline.stl");
    write_stl(&stl, &[[at(-1.0, 0.0), at(1.0, 0.0), at(1.0, 0.5)], [at(-1.0, 0.0), at(-1.0, -0.5), at(1.0, 0.0)]]);
    let r = 0.01;
    let start = [0, 1, 2].map(|k| 0.5 * t[k] + 0.999 * r * n[k]);
    let source = format!(
        r#"
        fn roll(mesh, stl, start, n) {{
            let sim = dem(#{{ seed: 1 }});
            let steel = sim.material(#{{ name: "steel", density: 7800.0 }});
            sim.contact_law("linear", #{{ kn: 1e5, kt_ratio: 0.5, friction: 30.0 }});
            if mesh {{ sim.wall_mesh(steel, stl); }} else {{ sim.wall_plane(steel, [0.0, 0.0, 0.0], n); }}
            sim.sphere(steel, start, {r});
            sim.gravity([0.0, 0.0, -9.81]);
            sim.dt(0.1 * sim.critical_dt());
            let most = 0;
            for k in 0..40 {{
                sim.run_steps(100);
                most = max(most, sim.contacts().len());
            }}
            #{{ x: sim.positions()[0], most: most, time: sim.time }}
        }}
        let plane = roll(false, "{stl}", {start:?}, {n:?});
        let mesh = roll(true, "{stl}", {start:?}, {n:?});
        summary("plane_x", plane.x[0]);
        summary("plane_y", plane.x[1]);
        summary("plane_z", plane.x[2]);
        summary("mesh_x", mesh.x[0]);
        summary("mesh_y", mesh.x[1]);
        summary("mesh_z", mesh.x[2]);
        summary("most_contacts", mesh.most);
        summary("time", plane.time);
        "#,
        stl = stl.display()
    );
    let s = common::summary_of(&run_text("mesh_wall_incline", &source));
    let get = |k: &str| s[k].as_f64().unwrap();
    for axis in ["x", "y", "z"] {
        let (p, m) = (get(&format!("plane_{axis}")), get(&format!("mesh_{axis}")));
        assert!((p - m).abs() < 1e-9, "{axis}: plane {p}, mesh {m}");
    }
    assert_eq!(s["most_contacts"].as_i64(), Some(1), "over the seam: one contact");
    // It did roll down: a rolling solid sphere accelerates at 5/7 g sin(theta) along the slope.
    let travelled = 0.5 - (get("plane_x") * t[0] + get("plane_z") * t[2]);
    let expected = 0.5 * 5.0 / 7.0 * 9.81 * theta.sin() * get("time").powi(2);
    assert!((travelled - expected).abs() < 0.02 * expected, "{travelled} m down the slope, rolling gives {expected}");
}

/// The 12 triangles of the cube [lo, hi]^3.
fn cube(lo: f64, hi: f64) -> Vec<Triangle> {
    let v = |i: usize| {
        [if i & 1 == 0 { lo } else { hi }, if i & 2 == 0 { lo } else { hi }, if i & 4 == 0 { lo } else { hi }]
    };
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    faces.iter().flat_map(|f| [[v(f[0]), v(f[1]), v(f[2])], [v(f[0]), v(f[2]), v(f[3])]]).collect()
}

#[test]
fn a_shaken_closed_box_of_triangles_holds_its_spheres() {
    let stl = root().join("target/test-out/mesh_wall_inputs/box.stl");
    let (side, amplitude, frequency) = (0.1, 0.01, 10.0);
    write_stl(&stl, &cube(0.0, side));
    let source = format!(
        r#"
        let sim = dem(#{{ seed: 3 }});
        let glass = sim.material(#{{ name: "glass", density: 2500.0 }});
        sim.contact_law("visco_elastic", #{{ kn: 2e4, kt_ratio: 0.3, friction: 25.0, restitution: 0.7 }});
        let box = sim.wall_mesh(glass, "{stl}");
        sim.cloud(glass, [0.005, 0.005, 0.005], [0.095, 0.095, 0.095], #{{ count: 300, radius: [0.003, 0.004] }});
        sim.gravity([0.0, 0.0, -9.81]);
        sim.dt(0.2 * sim.critical_dt());
        let w = 2.0 * PI() * {frequency};
        sim.wall_velocity(box, "z", |t| {amplitude} * w * cos(w * t));
        sim.wall_velocity(box, "x", |t| 0.5 * {amplitude} * w * cos(w * t));
        sim.run_until(0.3);
        summary("walls", box.len());
        summary("spheres", sim.positions().len());
        let shift = sim.wall_position(box);
        let lo = [1e9, 1e9, 1e9];
        let hi = [-1e9, -1e9, -1e9];
        for x in sim.positions() {{
            for k in 0..3 {{
                lo[k] = min(lo[k], x[k] - shift[k]);
                hi[k] = max(hi[k], x[k] - shift[k]);
            }}
        }}
        summary("lo", lo);
        summary("hi", hi);
        summary("force", sim.wall_force(box));
        "#,
        stl = stl.display()
    );
    let s = common::summary_of(&run_text("mesh_wall_box", &source));
    assert_eq!(s["walls"].as_i64(), Some(12));
    assert_eq!(s["spheres"].as_i64(), Some(300), "spheres were lost");
    // Every centre within the box (relative to its first corner, which moved with it), at
    // least most of a radius from the faces.
    let (lo, hi) = (s["lo"].as_array().unwrap(), s["hi"].as_array().unwrap());
    for k in 0..3 {
        let (l, h) = (lo[k].as_f64().unwrap(), hi[k].as_f64().unwrap());
        assert!(l > 0.0 && h < side, "axis {k}: centres from {l} to {h}, outside [0, {side}]");
    }
}

#[test]
fn a_wall_mesh_from_a_gmsh_surface_is_refused_without_its_group_and_placed_with_one() {
    let file = root().join("tests/meshes/wedge_block.msh").display().to_string();
    let setup = r#"let sim = dem(); let m = sim.material(#{ name: "steel", density: 7800.0 });"#;
    let e = run_text_err("mesh_wall_no_group", &format!("{setup}\nsim.wall_mesh(m, \"{file}\");"));
    assert!(e.contains("group") && e.contains("line 2"), "{e}");
    let e =
        run_text_err("mesh_wall_volume", &format!("{setup}\nsim.wall_mesh(m, \"{file}\", #{{ group: \"block\" }});"));
    assert!(e.contains("volumes") && e.contains("surfaces"), "{e}");
    // The base of the wedge (a unit square in z = 0), raised by 1 and doubled in size: a sphere
    // set down on it comes to rest there.
    let out = run_text(
        "mesh_wall_gmsh",
        &format!(
            r#"{setup}
            let bottom = sim.wall_mesh(m, "{file}", #{{ group: "bottom", scale: 2.0, translate: [0.0, 0.0, 1.0] }});
            sim.contact_law("linear", #{{ kn: 1e5, kt_ratio: 0.5, friction: 30.0 }});
            sim.sphere(m, [1.5, 1.5, 1.0594], 0.06);
            sim.gravity([0.0, 0.0, -9.81]);
            sim.damping(0.3);
            sim.dt(0.1 * sim.critical_dt());
            sim.run_steps(4000);
            summary("force", sim.wall_force(bottom));
            summary("weight", 7800.0 * 4.0 / 3.0 * PI() * 0.06 * 0.06 * 0.06 * 9.81);
            "#
        ),
    );
    let s = common::summary_of(&out);
    let fz = s["force"][2].as_f64().unwrap();
    let weight = s["weight"].as_f64().unwrap();
    // At rest the surface carries the sphere's weight.
    assert!((-fz - weight).abs() < 1e-3 * weight, "the base carries {fz} N of {weight} N");
}

#[test]
fn a_ball_rolling_on_a_turntable_of_triangles_circles_at_two_sevenths_of_its_rate() {
    // A solid ball rolling without slip on a table turning at Omega moves on a circle, fixed in
    // the lab, at 2/7 Omega (I / (I + m r^2) of it, I = 2/5 m r^2). The table: a square of two
    // triangles spinning about the vertical through its centre.
    let stl = root().join("target/test-out/mesh_wall_inputs/table.stl");
    let (omega, rho, r) = (2.0, 0.3, 0.01);
    // The orbit: radius 7/2 rho about a point 5/2 rho from the centre; the table holds it.
    let h = 1.2 * 6.0 * rho;
    write_stl(&stl, &[[[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0]], [[-h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]]]);
    let source = format!(
        r#"
        let sim = dem(#{{ seed: 1 }});
        let steel = sim.material(#{{ name: "steel", density: 7800.0 }});
        sim.contact_law("linear", #{{ kn: 1e5, kt_ratio: 1.0, friction: 45.0 }});
        let table = sim.wall_mesh(steel, "{stl}");
        sim.wall_spin(table, [0.0, 0.0, {omega}], [0.0, 0.0, 0.0]);
        let m = 7800.0 * 4.0 / 3.0 * PI() * {r} * {r} * {r};
        // On the table, carried at its surface's velocity, not spinning: no slip at the start.
        let id = sim.sphere(steel, [{rho}, 0.0, {r} - m * 9.81 / 1e5], {r}, #{{ velocity: [0.0, {omega} * {rho}, 0.0] }});
        sim.gravity([0.0, 0.0, -9.81]);
        sim.dt(0.05 * sim.critical_dt());
        let t = [];
        let vx = [];
        let vy = [];
        for k in 0..100 {{
            sim.run_until(0.05 * (k + 1));
            let v = sim.body(id).velocity;
            t.push(sim.time);
            vx.push(v[0]);
            vy.push(v[1]);
        }}
        summary("t", t);
        summary("vx", vx);
        summary("vy", vy);
        "#,
        stl = stl.display()
    );
    let s = common::summary_of(&run_text("mesh_wall_turntable", &source));
    let series = |k: &str| s[k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect::<Vec<_>>();
    let (t, vx, vy) = (series("t"), series("vx"), series("vy"));
    // The velocity turns with the ball's orbit: unwrap its angle and fit the rate.
    let mut angle = vec![vy[0].atan2(vx[0])];
    for k in 1..t.len() {
        let a = vy[k].atan2(vx[k]);
        let last = angle[k - 1];
        let turns = ((last - a) / std::f64::consts::TAU).round();
        angle.push(a + turns * std::f64::consts::TAU);
    }
    let (n, st, sa) = (t.len() as f64, t.iter().sum::<f64>(), angle.iter().sum::<f64>());
    let stt: f64 = t.iter().map(|x| x * x).sum();
    let sta: f64 = t.iter().zip(&angle).map(|(x, a)| x * a).sum();
    let rate = (n * sta - st * sa) / (n * stt - st * st);
    let expected = 2.0 / 7.0 * omega;
    assert!((rate - expected).abs() < 0.01 * expected, "the ball circles at {rate} rad/s, rolling gives {expected}");
    // And its speed stays that of the start (no slip, no loss).
    let speed = |k: usize| vx[k].hypot(vy[k]);
    assert!((speed(t.len() - 1) - omega * rho).abs() < 0.01 * omega * rho, "speed {}", speed(t.len() - 1));
}

/// A saved state holds the triangles (with their neighbours) and the spheres' contacts with them:
/// a run resumed from it goes on bit for bit as the run that wrote it, the box sliding and the
/// spheres tumbling in it.
#[test]
fn a_saved_state_with_a_moving_box_of_triangles_resumes_bit_for_bit() {
    let registry = granite_plugins::default_registry();
    let build = || {
        let mut sim = granite_core::dem::DemSim::new();
        let m = sim.world.add_material("glass", 2500.0).unwrap();
        let law: granite_core::registry::ParamMap =
            [("kn", 1e4), ("kt_ratio", 0.5), ("friction", 25.0)].iter().map(|(k, v)| (k.to_string(), *v)).collect();
        sim.world.set_contact_law(registry.build_contact_law("linear", &law).unwrap(), None).unwrap();
        for mut wall in granite_core::dem::mesh_walls::mesh_walls(&cube(0.0, 0.05), "box", m).unwrap() {
            wall.velocity = [0.02, 0.0, 0.01];
            sim.world.add_wall(wall);
        }
        for i in 0..5 {
            for j in 0..5 {
                for k in 0..4 {
                    let x = [0.006 + 0.0095 * i as f64, 0.006 + 0.0095 * j as f64, 0.006 + 0.0095 * k as f64];
                    sim.world.add_sphere(m, x, 0.004, [0.05 * (j as f64 - 2.0), 0.0, 0.0]).unwrap();
                }
            }
        }
        sim.world.gravity = [0.0, 0.0, -9.81];
        sim.world.set_damping(0.3).unwrap();
        sim.set_skin(0.002).unwrap();
        let dt = 0.2 * sim.world.critical_dt().unwrap();
        sim.world.set_dt(dt).unwrap();
        sim
    };
    let (straight, written, resumed) = straight_and_resumed(build, 1500, "mesh_walls_state");
    let touching = written.world.contacts.sphere_walls.touching_count();
    assert!(touching >= 5, "the saved state has {touching} wall contacts");
    let (a, b) = (&straight.world, &resumed.world);
    assert!(a.spheres.x == b.spheres.x && a.spheres.v == b.spheres.v && a.spheres.w == b.spheres.w);
    assert_eq!(a.contacts.sphere_walls.history, b.contacts.sphere_walls.history);
    assert!(a.walls.iter().zip(&b.walls).all(|(p, q)| p.position == q.position && p.shape == q.shape));
}
