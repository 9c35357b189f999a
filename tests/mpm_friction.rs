//! Coulomb friction on the floor (CB-Geo's friction constraint): a block sliding on a floor with
//! friction coefficient mu decelerates at mu g until it stops.

use crate::common;

fn slide(mu: f64, v0: f64, t_end: f64) -> f64 {
    let src = format!(
        r#"
let sim = mpm(#{{ dim: 2, cell: 0.05, cells: [40, 6] }});
let m = sim.material("linear_elastic", #{{ density: 2000.0, young: 1e8, poisson: 0.2 }});
sim.fill_box(m, [0.1, 0.0], [0.5, 0.2], #{{ per_cell: 2, velocity: [{v0}, 0.0] }});
sim.gravity([0.0, -9.81]);
sim.fix("y-", "y");
sim.friction("y-", {mu});
sim.velocity_update("PIC");
sim.dt(0.25 * sim.critical_dt());
sim.run_until({t_end});
"#
    );
    let out = common::run_text(&format!("friction_{mu}_{t_end}"), &src);
    // Speed of the block from its kinetic energy: it slides as one body, Ek = m v^2 / 2.
    let (h, rows) = common::read_csv(&out.join("series.csv"));
    let ek = rows.last().unwrap()[common::column(&h, "kinetic_energy")];
    let mass = 2000.0 * 0.4 * 0.2;
    (2.0 * ek / mass).sqrt()
}

#[test]
fn sliding_block_decelerates_at_mu_g() {
    let (mu, v0, g) = (0.3, 1.0, 9.81);
    let t = 0.2;
    let v = slide(mu, v0, t);
    let expected = v0 - mu * g * t;
    assert!((v - expected).abs() < 0.05 * v0, "v({t}) = {v}, Coulomb: {expected}");
    // Frictionless: the block keeps its speed.
    let v_free = slide(0.0, v0, t);
    assert!((v_free - v0).abs() < 0.01 * v0, "frictionless block slowed to {v_free}");
}
