//! Contact laws (YADE's split: the engine computes contact geometry for a shape pair, the law turns
//! geometry, per-contact parameters and history into a force). A law is chosen per material pair.
//!
//! Conventions: `normal` points from particle 1 to particle 2; `overlap` is positive in contact;
//! velocities are those of particle 2 relative to particle 1 at the contact point; the law returns
//! the force **on particle 1** (particle 2 gets its opposite) and an extra moment on particle 1
//! (rolling/twisting resistance; particle 2 gets its opposite). The engine adds the lever-arm torques.

use crate::error::Result;
use crate::math::Vec3;
use crate::params::{ParamSpec, Params};

/// Young's modulus (Pa, infinite for a rigid body) and Poisson's ratio of a material.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Elastic {
    pub young: f64,
    pub poisson: f64,
}

/// What a law knows about one contact pair when the pair is first met (to set its parameters).
#[derive(Debug, Clone, Copy)]
pub struct PairInfo {
    /// Radii of the two particles; a wall has an infinite radius.
    pub radius: [f64; 2],
    /// Masses of the two bodies; a wall has an infinite mass.
    pub mass: [f64; 2],
    /// A reproducible seed for this pair (from the particle ids and the simulation seed).
    pub seed: u64,
    /// Elastic constants of the two materials, where they were given (`sim.material(#{ young,
    /// poisson })`); a law that combines them (Hertz's `E*`) reads them here.
    pub elastic: [Option<Elastic>; 2],
}

impl PairInfo {
    /// `m1 m2 / (m1 + m2)`, or the finite mass against a wall.
    pub fn effective_mass(&self) -> f64 {
        let [a, b] = self.mass;
        if a.is_infinite() {
            b
        } else if b.is_infinite() {
            a
        } else {
            a * b / (a + b)
        }
    }

    /// `r1 r2 / (r1 + r2)`, or the finite radius against a wall.
    pub fn effective_radius(&self) -> f64 {
        let [a, b] = self.radius;
        if a.is_infinite() {
            b
        } else if b.is_infinite() {
            a
        } else {
            a * b / (a + b)
        }
    }

    /// The smaller radius.
    pub fn min_radius(&self) -> f64 {
        self.radius[0].min(self.radius[1])
    }
}

/// A batch of touching contacts. `normal` ... `moment` have one entry per contact; `params` and
/// `history` are those of the pair list the contacts come from, `strides` values per pair, and
/// `slot[e]` is the pair of contact `e` in them (increasing): a law reads and updates them in
/// place, through [`ContactBatch::for_each`].
pub struct ContactBatch<'a> {
    pub normal: &'a [Vec3],
    pub overlap: &'a [f64],
    /// Velocity of particle 2 relative to particle 1 at the contact point.
    pub rel_velocity: &'a [Vec3],
    /// Angular velocity of particle 2 minus that of particle 1; empty when no law of the
    /// simulation resists rotation (see [`ContactLaw::resists_rotation`]), and then zero.
    pub rel_spin: &'a [Vec3],
    pub slot: &'a [u32],
    /// Values per pair in `params` and `history`: at least the law's own counts (a pair list
    /// shared by several laws is laid out for the largest).
    pub strides: (usize, usize),
    pub params: &'a [f64],
    pub history: &'a mut [f64],
    /// Output: force on particle 1.
    pub force: &'a mut [Vec3],
    /// Output: extra moment on particle 1 (not the lever-arm torque of `force`); empty, and the
    /// law's moments dropped, when no law of the simulation resists rotation.
    pub moment: &'a mut [Vec3],
    pub dt: f64,
}

/// One contact of a batch, as [`ContactBatch::for_each`] hands it to a law: `P` parameters and
/// `H` history values of its own.
pub struct Contact<'b, const P: usize, const H: usize> {
    pub normal: Vec3,
    pub overlap: f64,
    pub rel_velocity: Vec3,
    pub rel_spin: Vec3,
    pub params: &'b [f64; P],
    pub history: &'b mut [f64; H],
    /// The time step.
    pub dt: f64,
}

impl ContactBatch<'_> {
    pub fn len(&self) -> usize {
        self.overlap.len()
    }
    pub fn is_empty(&self) -> bool {
        self.overlap.is_empty()
    }

    /// Runs `law` on every contact (a law with `P` parameters and `H` history values per contact)
    /// and stores the force and extra moment on particle 1 it returns. `law.contact` should be
    /// `#[inline(always)]`: it is then inlined into this loop for certain, also where the loop is
    /// compiled for AVX2 (`granite_core::contact_kernel!`), where a closure could stay a separate,
    /// plainly compiled function called per contact.
    #[inline(always)]
    pub fn for_each<const P: usize, const H: usize, L: ContactPhysics<P, H>>(self, law: &mut L) {
        let (ps, hs) = self.strides;
        assert!(P <= ps && H <= hs, "batch laid out for another law");
        let n = self.len();
        let (normal, rel_velocity, slots) = (&self.normal[..n], &self.rel_velocity[..n], &self.slot[..n]);
        let (force, moment) = (&mut self.force[..n], self.moment);
        let (spin, moments) = (!self.rel_spin.is_empty(), !moment.is_empty());
        // The history after the last contact's pair: slots increase, so each contact splits its
        // own values off the front of what is left.
        let mut rest = self.history;
        let mut rest_from = 0usize;
        for e in 0..n {
            let slot = slots[e] as usize;
            let skip = slot.checked_sub(rest_from).expect("contact slots increase") * hs;
            let (own, tail) = std::mem::take(&mut rest)[skip..].split_at_mut(hs);
            (rest, rest_from) = (tail, slot + 1);
            let (Ok(params), Ok(history)) =
                (self.params[slot * ps..slot * ps + P].try_into(), (&mut own[..H]).try_into())
            else {
                unreachable!("slices of exactly P and H values")
            };
            let (f, m) = law.contact(Contact {
                normal: normal[e],
                overlap: self.overlap[e],
                rel_velocity: rel_velocity[e],
                rel_spin: if spin { self.rel_spin[e] } else { [0.0; 3] },
                params,
                history,
                dt: self.dt,
            });
            force[e] = f;
            if moments {
                moment[e] = m;
            }
        }
    }
}

/// One touching contact over one step, as the energy tracker hands it to its law: the geometry
/// and relative velocity the step's force was computed from, the pair's values and its history
/// before and after the step, and the force on particle 1.
pub struct ContactStep<'a> {
    pub normal: Vec3,
    pub overlap: f64,
    pub rel_velocity: Vec3,
    /// Relative velocity over the step, the mean of the half-step velocities before and after
    /// it: the force's work on the bodies is `force . mean_rel_velocity dt`.
    pub mean_rel_velocity: Vec3,
    /// Angular velocity of particle 2 minus that of particle 1, as the law saw it.
    pub rel_spin: Vec3,
    pub dt: f64,
    pub params: &'a [f64],
    pub history_before: &'a [f64],
    pub history_after: &'a [f64],
    pub force: Vec3,
}

/// The physics of one contact: force and extra moment on particle 1 (see [`ContactBatch`]).
pub trait ContactPhysics<const P: usize, const H: usize> {
    fn contact(&mut self, c: Contact<'_, P, H>) -> (Vec3, Vec3);
}

pub trait ContactLaw: Send + Sync {
    fn name(&self) -> &str;
    fn params(&self) -> &Params;
    /// Values stored per contact pair, set once by `init_pair`.
    fn param_count(&self) -> usize;
    /// History values per contact (tangential spring, rolling...), zeroed when a contact opens.
    fn history_count(&self) -> usize;
    /// Sets the per-pair parameters (stiffness, damping, friction, possibly drawn at random).
    fn init_pair(&self, info: &PairInfo, params: &mut [f64]);
    /// Forces of a batch of touching contacts.
    fn compute(&self, batch: ContactBatch<'_>);
    /// Names of the values `init_pair` stores per contact (shown when contacts are listed); a
    /// law that does not name them shows `p0`, `p1`...
    fn pair_param_names(&self) -> &[&'static str] {
        &[]
    }
    /// Why this law cannot make a contact between these two bodies (a modulus neither the law nor
    /// the materials give), checked before a run for every pair of materials that may meet.
    fn check_pair(&self, _info: &PairInfo) -> std::result::Result<(), String> {
        Ok(())
    }
    /// Whether the law reads relative spins or returns moments (rolling/twisting resistance).
    /// When no law of a simulation does, the engine computes neither.
    fn resists_rotation(&self) -> bool {
        true
    }
    /// Largest normal stiffness a pair can get (for the critical time step), given its info.
    fn max_normal_stiffness(&self, info: &PairInfo) -> f64;
    /// Normal stiffness of a pair from its parameters (NaN when the law has none).
    fn normal_stiffness(&self, _params: &[f64]) -> f64 {
        f64::NAN
    }
    /// Tangent normal and tangential stiffnesses `(dF_n/dδ, dF_t/du_t)` of a touching pair at
    /// `overlap` (for the stability limit of a packing, `DemSim::stable_dt`). By default the
    /// normal stiffness and no tangential one.
    fn tangent_stiffness(&self, _overlap: f64, params: &[f64]) -> (f64, f64) {
        (self.normal_stiffness(params), 0.0)
    }
    /// Elastic energy stored in one contact (for energy balances).
    fn elastic_energy(&self, _overlap: f64, _params: &[f64], _history: &[f64]) -> f64 {
        0.0
    }
    /// Whether [`ContactLaw::dissipation`] accounts for every loss of the law (the energy tracker
    /// refuses a law that does not: its balance could not close).
    fn tracks_dissipation(&self) -> bool {
        false
    }
    /// Energy the contact dissipated in one step: `(friction, viscous)`, J. Friction: the
    /// tangential force times the slip of the step (the part of the tangential displacement the
    /// Coulomb limit took off the spring); viscous: the dashpot's force times the overlap's change
    /// over the step (`-mean_rel_velocity . n dt`).
    fn dissipation(&self, _step: &ContactStep<'_>) -> (f64, f64) {
        (0.0, 0.0)
    }
    /// The law as a device's kernel runs it (the RVEs of `dem_rve` on a GPU), or why it cannot:
    /// a law that has a device form keeps it beside its Rust code.
    fn device_form(&self) -> std::result::Result<DeviceLaw, String> {
        Err(format!("contact law \"{}\" has no device form", self.name()))
    }
}

/// A contact law in a device kernel's language (WGSL, f64): the text defines
///
/// `fn contact_stiffness(ra: f64, rb: f64, overlap: f64) -> vec2<f64>`
///
/// returning the pair's `(k_n, k_t)` as [`ContactLaw::tangent_stiffness`] gives them (the
/// device's time-step check), and
///
/// `fn contact_law(h: u32, ra: f64, rb: f64, n: vec3<f64>, overlap: f64, rel_v: vec3<f64>,
/// spin: vec3<f64>, dt: f64) -> Law`
///
/// returning the force and extra moment on the first sphere of a touching pair (`n` from the first
/// sphere to the second, `rel_v` the second's velocity at the contact point minus the first's,
/// `spin` the second's angular velocity minus the first's), with its constants read by
/// `law_constant(i)` and its history (`history_count()` values, 7 at most) at `pf[h + k]`, zero
/// when the contact opened. The kernel (`gpu/src/rve.wgsl`) gives it the helpers `sdot`, `scross`,
/// `rotate_into_plane`, `beyond_scale` and `spring_slider`. Its sums must follow the law's Rust
/// code operation by operation: where the driver fuses no multiply-add the device then computes
/// the CPU engine's numbers bit for bit.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceLaw {
    pub wgsl: &'static str,
    /// At most [`DeviceLaw::MOST_CONSTANTS`].
    pub constants: Vec<f64>,
}

impl DeviceLaw {
    pub const MOST_CONSTANTS: usize = 16;
}

pub trait ContactLawFactory: Send + Sync {
    fn name(&self) -> &str;
    fn param_specs(&self) -> &[ParamSpec];
    fn build(&self, params: Params) -> Result<Box<dyn ContactLaw>>;
    fn description(&self) -> &str {
        ""
    }
}

/// Uniform number in [0, 1) from a seed and a stream index: splitmix64, so that a pair's random
/// properties depend only on the pair, never on the order contacts are met or the thread count.
pub fn uniform(seed: u64, stream: u64) -> f64 {
    let mut z = seed.wrapping_add(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15)).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Contact laws by name, as a checkpoint's objects (the RVEs of `dem_rve`) need them to be
/// restored: the registry, seen from the extension points without their depending on it.
pub trait ContactLawSource {
    fn build_contact_law(
        &self,
        name: &str,
        given: &crate::params::ParamMap,
    ) -> crate::error::Result<Box<dyn ContactLaw>>;
    /// The body kind of this name (a saved state holding bodies of it).
    fn body_kind(&self, name: &str) -> crate::error::Result<std::sync::Arc<dyn crate::ext::BodyKindFactory>> {
        Err(crate::GraniteError::Setup(format!("no body kind \"{name}\" here")))
    }
    /// The geometries of pairs of body families (a saved state holding bodies of two families).
    fn body_pair_geometries(&self) -> Vec<std::sync::Arc<dyn crate::ext::BodyPairGeometry>> {
        Vec::new()
    }
    /// The RVE device of this name (a checkpoint of RVEs that ran on one).
    fn rve_device(&self, name: &str) -> crate::error::Result<std::sync::Arc<dyn crate::ext::RveDevice>> {
        Err(crate::GraniteError::Setup(format!("no RVE device \"{name}\" here")))
    }
}
