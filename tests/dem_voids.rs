//! Void ratio methods (thesis 2.3.3) against the exact value of a regular packing.

use granite_core::dem::voids::{
    grains, void_ratio_bounding_box, void_ratio_sub_volume, void_ratio_tetrahedra, SubVolume,
};
use granite_core::dem::DemSim;

#[test]
fn void_ratio_methods_agree_with_a_simple_cubic_packing() {
    let (n, r) = (10, 0.01);
    let mut sim = DemSim::new();
    let m = sim.world.add_material("m", 2500.0).unwrap();
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let x = [(2 * i + 1) as f64 * r, (2 * j + 1) as f64 * r, (2 * k + 1) as f64 * r];
                sim.world.add_sphere(m, x, r, [0.0; 3]).unwrap();
            }
        }
    }
    // Simple cubic: one sphere per cube of side 2r.
    let exact = 8.0 / (4.0 / 3.0 * std::f64::consts::PI) - 1.0;
    let g = grains(&sim);
    let e_ref = void_ratio_bounding_box(&g);
    assert!((e_ref - exact).abs() < 1e-9, "bounding box: {e_ref} vs {exact}");
    // C = 0.8 puts the sub-volume's faces on lattice planes (0.2 L = 4 r).
    let e_sub = void_ratio_sub_volume(&g, &SubVolume::homothetic_box(&g, 0.8), 2000, 1);
    assert!((e_sub - exact).abs() < 0.01 * exact, "sub-volume: {e_sub} vs {exact}");
    let (e_tet, v_tot, _) = void_ratio_tetrahedra(&g, 200, 1);
    let hull = (2.0 * r * (n - 1) as f64).powi(3);
    assert!((v_tot - hull).abs() < 1e-6 * hull, "tetrahedra cover {v_tot}, the hull is {hull}");
    assert!((e_tet - exact).abs() < 0.01 * exact, "tetrahedra: {e_tet} vs {exact}");
}

/// The same packing of potential particles with k = 1 (spheres of radius R): the sub-volume and
/// tetrahedron methods see their potentials and give the packing's void ratio, within 1 % and
/// the 0.3 % their volume's integration leaves.
#[test]
fn void_ratio_of_a_simple_cubic_packing_of_potential_particles() {
    use granite_core::ext::BodyKindFactory;
    use granite_plugins::shape::potential::shape::box_planes;
    use granite_plugins::shape::potential::{add, planes_params, NewPotential, PotentialBody, PotentialPlanesKind};
    let (n, r) = (10, 0.01);
    let ball = PotentialPlanesKind.build_from(&planes_params(&box_planes([0.5 * r; 3]), 0.3 * r, r, 1.0)).unwrap();
    let mut sim = DemSim::new();
    let m = sim.world.add_material("m", 2500.0).unwrap();
    let s = PotentialBody::shape_of(ball.as_ref()).unwrap().sphere_centre;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                // The centre of mass sits where the integration put it, a hair off the sphere's centre.
                let x = [(2 * i + 1) as f64 * r - s[0], (2 * j + 1) as f64 * r - s[1], (2 * k + 1) as f64 * r - s[2]];
                let q = nalgebra::UnitQuaternion::identity();
                let new =
                    NewPotential { shape: ball.clone(), material: m, x, q, v: [0.0; 3], w: [0.0; 3], fixed: false };
                add(&mut sim, new).unwrap();
            }
        }
    }
    let exact = 8.0 / (4.0 / 3.0 * std::f64::consts::PI) - 1.0;
    let g = grains(&sim);
    assert_eq!(g.len(), n * n * n);
    let e_sub = void_ratio_sub_volume(&g, &SubVolume::homothetic_box(&g, 0.8), 2000, 1);
    assert!((e_sub - exact).abs() < 0.013 * exact, "sub-volume: {e_sub} vs {exact}");
    let (e_tet, _, _) = void_ratio_tetrahedra(&g, 200, 1);
    assert!((e_tet - exact).abs() < 0.013 * exact, "tetrahedra: {e_tet} vs {exact}");
}
