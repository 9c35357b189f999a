//! The energy tracker (YADE's `O.trackEnergy`): the energy in the system and every way it came
//! in or went out, step by step, so that their balance can be checked.
//!
//! At step n (forces from the positions `x_n`, velocities stored at half steps):
//! - kinetic `1/2 m v_(n-1/2) . v_(n+1/2)` (and the same for rotations): the kinetic energy that,
//!   with the elastic energy at `x_n`, leapfrog conserves exactly for linear springs;
//! - gravitational `-m g . x_n`, elastic: the contact laws' `elastic_energy` at `x_n`;
//! - friction and viscous: what each contact's law says it dissipated in the step
//!   (`ContactLaw::dissipation`), summed;
//! - damping: the work Cundall's damping took, `-m (a - F/m - g) . v_n dt` per free degree of
//!   freedom, `a = (v_(n+1/2) - v_(n-1/2))/dt` and `v_n` the mean of the two;
//! - boundary work: done on the spheres and bodies by moving walls (each wall contact's force
//!   times the wall's velocity), by fixed bodies moving at their own velocity and spin (the loads
//!   on them times those), by blocked degrees of freedom (the force that kept their velocity), and
//!   by external loads.
//!
//! Clumps and the bodies of plugin kinds (capsules, potential particles) are rigid bodies: their
//! rotation is booked by Euler's equations in the world frame.
//!
//! `kinetic + gravitational + elastic + friction + viscous + damping - boundary` stays constant.

pub(crate) mod booking;

/// What the tracker holds: the accumulated exchanges and the last step's energies.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct EnergyTracker {
    pub kinetic: f64,
    pub gravitational: f64,
    pub elastic: f64,
    pub friction: f64,
    pub viscous: f64,
    pub damping: f64,
    pub boundary_work: f64,
    /// The balance at the first tracked step.
    pub initial_total: Option<f64>,
}

impl EnergyTracker {
    /// `kinetic + gravitational + elastic + dissipated - boundary work`: constant.
    pub fn total(&self) -> f64 {
        self.kinetic + self.gravitational + self.elastic + self.friction + self.viscous + self.damping
            - self.boundary_work
    }

    pub fn entries(&self) -> [(&'static str, f64); 9] {
        [
            ("kinetic", self.kinetic),
            ("gravitational", self.gravitational),
            ("elastic", self.elastic),
            ("friction", self.friction),
            ("viscous", self.viscous),
            ("damping", self.damping),
            ("boundary_work", self.boundary_work),
            ("total", self.total()),
            ("initial_total", self.initial_total.unwrap_or(f64::NAN)),
        ]
    }
}
