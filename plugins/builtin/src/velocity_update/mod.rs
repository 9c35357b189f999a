//! Velocity-update strategies of thesis table 3.1. Each is a blend of the PIC velocity and the FLIP
//! velocity, with the point moved either by the PIC velocity or by its own new velocity:
//!
//! | name   | new point velocity                    | displacement velocity |
//! |--------|---------------------------------------|-----------------------|
//! | PIC    | V_PIC (3.28)                          | V_PIC (3.29)          |
//! | FLIP   | V_FLIP = V + sum a N dt (3.30)        | V_PIC (3.31)          |
//! | NFLIP  | V_FLIP                                | V_FLIP (3.32)         |
//! | FLIPX  | (1-P) V_PIC + P V_FLIP (3.33)         | V_PIC                 |
//! | NFLIPX | (1-P) V_PIC + P V_FLIP                | that velocity (3.34)  |
//! | APIC   | V_PIC, with affine momentum transfer  | V_PIC                 |
//! | ASFLIP | V_PIC + alpha (V - V_grid), affine    | V_PIC + beta (V - V_grid) |
//!
//! ASFLIP (Fei, Guo, Wu, Huang & Gao 2021) keeps APIC's affine transfer and adds back a fraction
//! alpha of the point's own velocity deviation from the grid velocity before this step's forces,
//! `V - V_grid` with `V_grid = sum_i N_i V_i^n = V_PIC - sum_i N_i a_i dt`. The point moves with
//! beta of that deviation: `beta_min` (0: moved as APIC, with the grid) while the point is
//! compressed, `beta_max` once it has dilated (volumetric strain above zero), so points that
//! separate from the body are not held to the grid's averaged velocity.

use granite_core::ext::{G2pBatch, VelocityUpdate, VelocityUpdateFactory};
use granite_core::params::{ParamSpec, Params};
use granite_core::registry::ParamMap;
use granite_core::Registry;
use std::sync::Arc;

#[derive(Debug, Clone)]
pub struct Blend {
    name: &'static str,
    /// Weight P of the FLIP velocity in the new point velocity.
    flip_weight: f64,
    /// Move with the new point velocity (N-variants) instead of V_PIC.
    move_with_new: bool,
    affine: bool,
    /// Parameters given at build (flip_ratio for the blends), to rebuild it.
    given: ParamMap,
}

impl VelocityUpdate for Blend {
    fn params(&self) -> ParamMap {
        self.given.clone()
    }
    fn name(&self) -> &str {
        self.name
    }
    fn affine(&self) -> bool {
        self.affine
    }
    fn update(&self, b: G2pBatch<'_>) {
        let p = self.flip_weight;
        for i in 0..b.v_old.len() {
            let (v0, vp, dv) = (b.v_old[i], b.v_pic[i], b.dv_grid[i]);
            let v_new = [
                (1.0 - p) * vp[0] + p * (v0[0] + dv[0]),
                (1.0 - p) * vp[1] + p * (v0[1] + dv[1]),
                (1.0 - p) * vp[2] + p * (v0[2] + dv[2]),
            ];
            b.v_new[i] = v_new;
            b.v_move[i] = if self.move_with_new { v_new } else { vp };
        }
    }
}

/// ASFLIP: affine transfer, a FLIP-like velocity increment with weight `alpha`, and the position
/// moved by `beta_max` of the point's own deviation where it has dilated, `beta_min` elsewhere.
#[derive(Debug, Clone)]
pub struct Asflip {
    alpha: f64,
    beta_min: f64,
    beta_max: f64,
}

impl VelocityUpdate for Asflip {
    fn name(&self) -> &str {
        "ASFLIP"
    }
    fn affine(&self) -> bool {
        true
    }
    fn params(&self) -> ParamMap {
        [("alpha", self.alpha), ("beta_min", self.beta_min), ("beta_max", self.beta_max)]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect()
    }
    fn update(&self, b: G2pBatch<'_>) {
        for i in 0..b.v_old.len() {
            let (v0, vp, dv, e) = (b.v_old[i], b.v_pic[i], b.dv_grid[i], &b.strain[i]);
            let dilated = e[0] + e[1] + e[2] > 0.0;
            let beta = if dilated { self.beta_max } else { self.beta_min };
            for a in 0..3 {
                // The point's velocity less the grid's before this step's forces, at the point.
                let own = v0[a] - (vp[a] - dv[a]);
                b.v_new[i][a] = vp[a] + self.alpha * own;
                b.v_move[i][a] = vp[a] + beta * own;
            }
        }
    }
}

struct AsflipFactory;

const ASFLIP_PARAMS: &[ParamSpec] = &[
    ParamSpec::optional("alpha", 0.95, "weight in [0, 1] of the point's own velocity deviation kept in its velocity"),
    ParamSpec::optional("beta_min", 0.0, "weight in [0, 1] of that deviation in the motion of a compressed point"),
    ParamSpec::optional("beta_max", 1.0, "weight in [beta_min, 1] of that deviation in the motion of a dilated point"),
];

impl VelocityUpdateFactory for AsflipFactory {
    fn name(&self) -> &str {
        "ASFLIP"
    }
    fn description(&self) -> &str {
        "affine separable FLIP (Fei et al. 2021): APIC's affine transfer, a FLIP-like increment with weight alpha, dilated points moved with their own velocity"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        ASFLIP_PARAMS
    }
    fn build(&self, params: Params) -> granite_core::Result<Box<dyn VelocityUpdate>> {
        let alpha = params.in_range("alpha", 0.0, 1.0, true)?;
        let beta_min = params.in_range("beta_min", 0.0, 1.0, true)?;
        let beta_max = params.in_range("beta_max", beta_min, 1.0, true)?;
        Ok(Box::new(Asflip { alpha, beta_min, beta_max }))
    }
}

struct BlendFactory {
    name: &'static str,
    description: &'static str,
    /// Fixed FLIP weight, or None to read `flip_ratio`.
    flip_weight: Option<f64>,
    move_with_new: bool,
    affine: bool,
}

const FLIP_RATIO: &[ParamSpec] =
    &[ParamSpec::optional("flip_ratio", 0.9, "P_FLIP in [0, 1]: weight of the FLIP velocity (eq. 3.33)")];

impl VelocityUpdateFactory for BlendFactory {
    fn name(&self) -> &str {
        self.name
    }
    fn description(&self) -> &str {
        self.description
    }
    fn param_specs(&self) -> &[ParamSpec] {
        if self.flip_weight.is_none() {
            FLIP_RATIO
        } else {
            &[]
        }
    }
    fn build(&self, params: Params) -> granite_core::Result<Box<dyn VelocityUpdate>> {
        let mut given = ParamMap::new();
        let flip_weight = match self.flip_weight {
            Some(w) => w,
            None => {
                let w = params.in_range("flip_ratio", 0.0, 1.0, true)?;
                given.insert("flip_ratio".into(), w);
                w
            }
        };
        Ok(Box::new(Blend {
            name: self.name,
            flip_weight,
            move_with_new: self.move_with_new,
            affine: self.affine,
            given,
        }))
    }
}

pub fn register(registry: &mut Registry) {
    let table = [
        ("PIC", "particle in cell: dissipative, robust", Some(0.0), false, false),
        ("FLIP", "fluid implicit particle: velocity from accelerations, moved with V_PIC", Some(1.0), false, false),
        ("NFLIP", "naturally modified FLIP: moved with its own velocity", Some(1.0), true, false),
        ("FLIPX", "blend of PIC and FLIP with weight flip_ratio", None, false, false),
        ("NFLIPX", "blend of PIC and FLIP, moved with the blended velocity", None, true, false),
        ("APIC", "affine particle in cell (Jiang et al. 2015)", Some(0.0), false, true),
    ];
    for (name, description, flip_weight, move_with_new, affine) in table {
        registry.add_velocity_update(Arc::new(BlendFactory { name, description, flip_weight, move_with_new, affine }));
    }
    registry.add_velocity_update(Arc::new(AsflipFactory));
}

/// A strategy by name, for tests and tools that do not go through a registry.
pub fn by_name(name: &str, flip_ratio: f64) -> granite_core::Result<Box<dyn VelocityUpdate>> {
    let mut reg = Registry::new();
    register(&mut reg);
    let mut given = ParamMap::new();
    if matches!(name.to_ascii_uppercase().as_str(), "FLIPX" | "NFLIPX") {
        given.insert("flip_ratio".into(), flip_ratio);
    }
    reg.build_velocity_update(name, &given)
}

#[cfg(test)]
mod tests {
    use super::*;
    use granite_core::math::{Vec3, Voigt};

    /// Runs a strategy on one point; returns (new velocity, displacement velocity).
    fn one_point(update: &dyn VelocityUpdate, v_old: Vec3, v_pic: Vec3, dv: Vec3, strain: Voigt) -> (Vec3, Vec3) {
        let (mut v_new, mut v_move) = ([[0.0; 3]], [[0.0; 3]]);
        update.update(G2pBatch {
            v_old: &[v_old],
            v_pic: &[v_pic],
            dv_grid: &[dv],
            strain: &[strain],
            v_new: &mut v_new,
            v_move: &mut v_move,
        });
        (v_new[0], v_move[0])
    }

    fn asflip(alpha: f64, beta_min: f64, beta_max: f64) -> Box<dyn VelocityUpdate> {
        let mut reg = Registry::new();
        register(&mut reg);
        let given: ParamMap =
            [("alpha", alpha), ("beta_min", beta_min), ("beta_max", beta_max)].map(|(k, v)| (k.into(), v)).into();
        reg.build_velocity_update("ASFLIP", &given).unwrap()
    }

    #[test]
    fn asflip_spans_apic_and_flip_and_moves_dilated_points_with_their_own_velocity() {
        let (v_old, v_pic, dv) = ([1.0, -2.0, 0.5], [0.4, 0.3, -0.1], [0.1, 0.2, 0.05]);
        let compressed = [-1e-3, -1e-3, 0.0, 0.0, 0.0, 0.0];
        let dilated = [2e-3, -1e-3, 0.0, 0.0, 0.0, 0.0];
        let flip: Vec3 = std::array::from_fn(|a| v_old[a] + dv[a]);
        // alpha = 0: APIC's velocity; alpha = 1: FLIP's (the grid's increment added to the old).
        assert_eq!(one_point(asflip(0.0, 0.0, 1.0).as_ref(), v_old, v_pic, dv, compressed), (v_pic, v_pic));
        let (v, moved) = one_point(asflip(1.0, 0.0, 1.0).as_ref(), v_old, v_pic, dv, compressed);
        let close = |a: Vec3, b: Vec3| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-15);
        assert!(close(v, flip) && close(moved, v_pic), "{v:?} {moved:?}");
        // A dilated point moves with beta_max of its deviation: all of it, its FLIP velocity.
        let (_, moved) = one_point(asflip(1.0, 0.0, 1.0).as_ref(), v_old, v_pic, dv, dilated);
        assert!(close(moved, flip), "{moved:?}");
        // beta_max below beta_min is refused.
        let mut reg = Registry::new();
        register(&mut reg);
        let given: ParamMap = [("beta_min", 0.5), ("beta_max", 0.2)].map(|(k, v)| (k.into(), v)).into();
        assert!(reg.build_velocity_update("ASFLIP", &given).is_err());
    }
}
