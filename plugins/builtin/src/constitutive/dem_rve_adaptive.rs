//! Similarity-based activation of a `dem_rve` material's RVEs (`adaptive: #{ coarsen, refine,
//! every }`): a point whose recent strain history and state are close to an active point's stops
//! stepping its own RVE and *follows* that point, taking its stress increment; it steps again
//! once the two have drifted apart.
//!
//! The distance between two points is an estimate of the relative stress error a follower
//! carries, so that the tolerances read as fractions of the stress:
//!
//! `d(i, r) = (|sigma_i - sigma_r| + K_r |h_i - h_r|) / max(p_i, p_r, p_mean)
//!           + |e_i - e_r| / (1 + e_r) + |Z_i - Z_r| / max(Z_r, 1)`
//!
//! - `sigma`: the points' stresses (tensor norm), `p` their mean pressures, `p_mean` the mean
//!   pressure of the material's points (at least `P_min` of eq. 4.2): near a free surface, where
//!   the pressure tends to zero, errors count against the stress that drives the flow;
//! - `h`: each point's strain increments summed with a fading weight `exp(-1/every)` a step (the
//!   strain of about the last `every` steps; granular fabrics forget older loading);
//! - `K_r`: the secant stiffness of `r`'s RVE, its fading sum of stress-increment norms over its
//!   fading sum of strain-increment norms, so that `K_r |h_i - h_r|` is the stress the two would
//!   drift apart by over the next check interval;
//! - `e` void ratio, `Z` coordination (the fabric the stress alone does not show).
//!
//! A follower whose borrowed increment would put it in tension (a cohesionless RVE cannot carry
//! any) steps again at once, whatever its distance.
//!
//! A follower's distance to the point it follows uses, instead of `h_i - h_r`, the strain by
//! which their paths actually differed since it began to follow (its *drift*, not faded): the
//! stress error it has accumulated. Every `every` steps, active points within `coarsen` of an
//! active point that leads become its followers (points are visited in index order; a point
//! that leads keeps leading while it has followers); at the end of every step, a follower beyond
//! `refine` becomes active again, by default from a copy of its leader's RVE (`Restart`).
//!
//! Everything here is a function of the MPM's data (strain increments, stresses, state
//! variables), which every process of a spread run holds in full: every process takes the same
//! decisions, whoever owns which RVE.

use granite_core::math::Voigt;
use serde::{Deserialize, Serialize};

/// The tolerances of `adaptive: #{ coarsen, refine, every }`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Distance under which an active point becomes a follower.
    pub coarsen: f64,
    /// Distance over which a follower becomes active again.
    pub refine: f64,
    /// MPM steps between two coarsening passes (and the memory of the strain history).
    pub every: u64,
    /// How a follower steps again.
    pub restart: Restart,
}

/// How a follower whose distance passed `refine` steps again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Restart {
    /// From a copy of its leader's RVE as the step left it (its stress becomes the copy's).
    CopyLeader,
    /// From its own RVE, frozen when it began to follow, which first takes in one increment
    /// all the strain it missed.
    OwnCaughtUp,
}

/// What the controller keeps of one material point between steps.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
struct History {
    /// The active point it follows, or None while it steps its own RVE.
    follows: Option<u32>,
    /// Fading sum of its strain increments (tensor components xx, yy, zz, xy, yz, xz).
    recent_strain: [f64; 6],
    /// Fading sums of the norms of its RVE's stress and strain increments (secant stiffness).
    stress_change: f64,
    strain_change: f64,
    /// Strain its RVE has not taken yet (engineering shear, like the MPM's increments).
    missed_strain: Voigt,
    /// Following: the strain by which its path has differed from its leader's since.
    drift: [f64; 6],
}

/// The activation state of one material's points.
#[derive(Debug, Clone)]
pub struct Activation {
    tolerances: Tolerances,
    /// Pressure floor of the relative distances (P_min of eq. 4.2).
    p_floor: f64,
    /// This step's stress scale: the mean pressure of the material's points (or `p_floor`).
    scale: f64,
    points: Vec<History>,
    /// Steps planned so far.
    steps: u64,
    /// Point-steps spent following, and the DEM steps their leaders took in them (the work the
    /// followers' own RVEs would have done, about).
    followed: Followed,
    /// This step: the strain each active point's RVE takes (None: it follows), and every
    /// point's stress and strain increment before the update.
    applied: Vec<Option<Voigt>>,
    before: Vec<Voigt>,
    increment: Vec<Voigt>,
}

/// What following spared so far.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct Followed {
    pub point_steps: u64,
    pub leader_dem_steps: f64,
}

/// Tensor components of an engineering-shear strain.
fn strain_tensor(e: &Voigt) -> [f64; 6] {
    [e[0], e[1], e[2], 0.5 * e[3], 0.5 * e[4], 0.5 * e[5]]
}

/// Frobenius norm of a symmetric tensor given by its components xx, yy, zz, xy, yz, xz.
fn tensor_norm(t: &[f64; 6]) -> f64 {
    (t[0] * t[0] + t[1] * t[1] + t[2] * t[2] + 2.0 * (t[3] * t[3] + t[4] * t[4] + t[5] * t[5])).sqrt()
}

fn difference(a: &[f64; 6], b: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|k| a[k] - b[k])
}

fn pressure(s: &Voigt) -> f64 {
    ((s[0] + s[1] + s[2]) / 3.0).abs()
}

/// What `plan` tells the law about one point this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Role {
    /// Its RVE takes this strain (its increment, plus what it missed while following).
    Steps(Voigt),
    /// It takes the stress increment of this point.
    Follows(usize),
}

/// The state variables the distance reads and a follower's update writes (`dem_rve`'s order).
pub mod state {
    pub const MEAN_STRESS: usize = 0;
    pub const DEVIATORIC_STRESS: usize = 1;
    pub const VOID_RATIO: usize = 2;
    pub const COORDINATION: usize = 3;
    pub const RATTLERS: usize = 4;
    pub const DEM_STEPS: usize = 5;
    pub const NO_CONTACTS: usize = 6;
    pub const DEM_SPHERE_STEPS: usize = 7;
}

impl Activation {
    pub fn new(tolerances: Tolerances, p_floor: f64) -> Activation {
        Activation {
            tolerances,
            p_floor: p_floor.max(f64::MIN_POSITIVE),
            scale: p_floor.max(f64::MIN_POSITIVE),
            points: Vec::new(),
            steps: 0,
            followed: Followed::default(),
            applied: Vec::new(),
            before: Vec::new(),
            increment: Vec::new(),
        }
    }

    /// Points appended: they start active.
    pub fn add(&mut self, count: usize) {
        self.points.extend(std::iter::repeat_n(History::default(), count));
    }

    /// Points removed: keep those whose flag is true. Followers of a removed point become active
    /// and catch up with the strain they missed at their next step.
    pub fn retain(&mut self, keep: &[bool]) {
        let mut new_index = Vec::with_capacity(keep.len());
        let mut next = 0u32;
        for &k in keep {
            new_index.push(k.then_some(next));
            next += u32::from(k);
        }
        let mut k = keep.iter();
        self.points.retain(|_| *k.next().unwrap_or(&true));
        for h in &mut self.points {
            if let Some(leader) = h.follows {
                h.follows = new_index.get(leader as usize).copied().flatten();
                if h.follows.is_none() {
                    h.drift = [0.0; 6];
                }
            }
        }
    }

    /// Points stepping their own RVE.
    pub fn active(&self) -> usize {
        self.points.iter().filter(|h| h.follows.is_none()).count()
    }

    /// The point each follows (None: active).
    #[cfg(test)]
    fn leaders(&self) -> Vec<Option<usize>> {
        self.points.iter().map(|h| h.follows.map(|l| l as usize)).collect()
    }

    /// Decides this step's roles from the points' strain increments, stresses and state
    /// variables (`stride` a point) before the update.
    pub fn plan(&mut self, dstrain: &[Voigt], stress: &[Voigt], state: &[f64], stride: usize) -> Vec<Role> {
        let n = dstrain.len();
        if self.points.len() < n {
            self.add(n - self.points.len());
        }
        let fade = (-1.0 / self.tolerances.every as f64).exp();
        let increments: Vec<[f64; 6]> = dstrain.iter().map(strain_tensor).collect();
        for (h, de) in self.points.iter_mut().zip(&increments) {
            h.recent_strain = std::array::from_fn(|k| fade * h.recent_strain[k] + de[k]);
        }
        let fabric = |i: usize, k: usize| state.get(i * stride + k).copied().unwrap_or(0.0);
        self.scale = (stress.iter().map(pressure).sum::<f64>() / n.max(1) as f64).max(self.p_floor);
        for i in 0..n {
            let Some(leader) = self.points[i].follows.map(|l| l as usize) else { continue };
            let step_drift = difference(&increments[i], &increments[leader]);
            let h = &mut self.points[i];
            h.drift = std::array::from_fn(|k| h.drift[k] + step_drift[k]);
        }
        if self.steps >= self.tolerances.every && self.steps.is_multiple_of(self.tolerances.every) {
            self.coarsen(&increments, stress, &fabric);
        }
        self.steps += 1;
        self.before = stress.to_vec();
        self.increment = dstrain.to_vec();
        self.applied.clear();
        let mut roles = Vec::with_capacity(n);
        for (h, de) in self.points.iter_mut().zip(dstrain) {
            let owed: Voigt = std::array::from_fn(|k| h.missed_strain[k] + de[k]);
            match h.follows {
                Some(leader) => {
                    if self.tolerances.restart == Restart::OwnCaughtUp {
                        h.missed_strain = owed;
                    }
                    self.applied.push(None);
                    roles.push(Role::Follows(leader as usize));
                }
                None => {
                    h.missed_strain = [0.0; 6];
                    self.applied.push(Some(owed));
                    roles.push(Role::Steps(owed));
                }
            }
        }
        roles
    }

    /// The distance of module docs between `i` and the active point `r`, with `strain` the
    /// norm of the strain by which their paths differ.
    fn distance(
        &self,
        i: usize,
        r: usize,
        strain: f64,
        stress: &[Voigt],
        fabric: &impl Fn(usize, usize) -> f64,
    ) -> f64 {
        let scale = pressure(&stress[i]).max(pressure(&stress[r])).max(self.scale);
        let lead = &self.points[r];
        let stiffness = if lead.strain_change > 0.0 { lead.stress_change / lead.strain_change } else { 0.0 };
        let stress_gap = tensor_norm(&difference(&stress[i], &stress[r]));
        let (e_i, e_r) = (fabric(i, state::VOID_RATIO), fabric(r, state::VOID_RATIO));
        let (z_i, z_r) = (fabric(i, state::COORDINATION), fabric(r, state::COORDINATION));
        // The fabric terms count in full even where the pressure is low: a loose RVE gaining
        // or losing contacts responds far from its neighbours (weighed by the pressure instead,
        // they let such RVEs follow, and the small column gained five times the kinetic energy).
        let fabric_gap = (e_i - e_r).abs() / (1.0 + e_r) + (z_i - z_r).abs() / z_r.max(1.0);
        (stress_gap + stiffness * strain) / scale + fabric_gap
    }

    /// Active points without followers, in index order, join the closest leader within
    /// `coarsen` (the lowest index on ties) or lead.
    fn coarsen(&mut self, increments: &[[f64; 6]], stress: &[Voigt], fabric: &impl Fn(usize, usize) -> f64) {
        let n = self.points.len().min(stress.len());
        let mut leads = vec![false; n];
        for h in &self.points[..n] {
            if let Some(l) = h.follows {
                leads[l as usize] = true;
            }
        }
        let mut leaders: Vec<usize> = (0..n).filter(|&i| leads[i]).collect();
        for i in 0..n {
            if self.points[i].follows.is_some() || leads[i] {
                continue;
            }
            let closest = leaders
                .iter()
                .map(|&r| {
                    let gap = tensor_norm(&difference(&self.points[i].recent_strain, &self.points[r].recent_strain));
                    (self.distance(i, r, gap, stress, fabric), r)
                })
                .filter(|(d, _)| *d < self.tolerances.coarsen)
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            match closest {
                Some((_, r)) => {
                    let h = &mut self.points[i];
                    h.follows = Some(r as u32);
                    h.drift = difference(&increments[i], &increments[r]);
                }
                None => leaders.push(i),
            }
        }
    }

    /// After the update of the active points (and, in a spread run, the all-gather of their
    /// results): each follower takes its leader's stress increment; its void ratio follows its
    /// own volume change, its contact counts its leader's. Updates the active points' stiffness.
    ///
    /// Then every follower past `refine` becomes active for the next step; with
    /// `Restart::CopyLeader` it takes its leader's stress and state variables now, and the
    /// returned copies (leader, follower) of RVEs must be made before the next update.
    pub fn complete(&mut self, stress: &mut [Voigt], state: &mut [f64], stride: usize) -> Vec<(usize, usize)> {
        let fade = (-1.0 / self.tolerances.every as f64).exp();
        let n = stress.len().min(self.points.len()).min(self.before.len());
        for i in 0..n {
            let Some(applied) = self.applied.get(i).copied().flatten() else { continue };
            let h = &mut self.points[i];
            h.stress_change = fade * h.stress_change + tensor_norm(&difference(&stress[i], &self.before[i]));
            h.strain_change = fade * h.strain_change + tensor_norm(&strain_tensor(&applied));
        }
        for i in 0..n {
            let Some(r) = self.points[i].follows.map(|l| l as usize) else { continue };
            stress[i] = std::array::from_fn(|k| self.before[i][k] + stress[r][k] - self.before[r][k]);
            if stride == 0 {
                continue;
            }
            let (mean, q) = granite_core::math::p_q(&stress[i]);
            let de = &self.increment[i];
            let (lead, own) = if r < i {
                let (a, b) = state.split_at_mut(i * stride);
                (&a[r * stride..(r + 1) * stride], &mut b[..stride])
            } else {
                let (a, b) = state.split_at_mut(r * stride);
                (&b[..stride], &mut a[i * stride..(i + 1) * stride])
            };
            own[state::MEAN_STRESS] = mean;
            own[state::DEVIATORIC_STRESS] = q;
            own[state::VOID_RATIO] = (1.0 + own[state::VOID_RATIO]) * (de[0] + de[1] + de[2]).exp() - 1.0;
            for k in [state::COORDINATION, state::RATTLERS, state::NO_CONTACTS] {
                own[k] = lead[k];
            }
            own[state::DEM_STEPS] = 0.0;
            self.followed.point_steps += 1;
            self.followed.leader_dem_steps += lead[state::DEM_STEPS];
        }
        let mut copies = Vec::new();
        for i in 0..n {
            let Some(r) = self.points[i].follows.map(|l| l as usize) else { continue };
            let drift = tensor_norm(&self.points[i].drift);
            let fabric = |p: usize, k: usize| state.get(p * stride + k).copied().unwrap_or(0.0);
            let tension = stress[i][0] + stress[i][1] + stress[i][2] > 0.0;
            if !tension && self.distance(i, r, drift, stress, &fabric) <= self.tolerances.refine {
                continue;
            }
            let h = &mut self.points[i];
            h.follows = None;
            h.drift = [0.0; 6];
            if self.tolerances.restart == Restart::CopyLeader {
                h.missed_strain = [0.0; 6];
                stress[i] = stress[r];
                // The copy's state variables, all but the work done by the point's own RVEs.
                for k in [
                    state::MEAN_STRESS,
                    state::DEVIATORIC_STRESS,
                    state::VOID_RATIO,
                    state::COORDINATION,
                    state::RATTLERS,
                    state::NO_CONTACTS,
                ] {
                    if stride > k {
                        state[i * stride + k] = state[r * stride + k];
                    }
                }
                copies.push((r, i));
            }
        }
        copies
    }

    /// What following spared so far.
    pub fn followed(&self) -> Followed {
        self.followed
    }

    /// The activation state for a checkpoint.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({ "steps": self.steps, "points": self.points, "followed": self.followed })
    }

    /// Restores what `to_json` wrote.
    pub fn load_json(&mut self, value: serde_json::Value) -> Result<(), String> {
        #[derive(Deserialize)]
        struct Saved {
            steps: u64,
            points: Vec<History>,
            followed: Followed,
        }
        let saved: Saved = serde_json::from_value(value).map_err(|e| e.to_string())?;
        if let Some(bad) = saved.points.iter().position(|h| h.follows.is_some_and(|l| l as usize >= saved.points.len()))
        {
            return Err(format!("point {bad} follows a point that does not exist"));
        }
        self.steps = saved.steps;
        self.points = saved.points;
        self.followed = saved.followed;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STRIDE: usize = 8;

    fn tolerances() -> Tolerances {
        Tolerances { coarsen: 0.02, refine: 0.05, every: 2, restart: Restart::CopyLeader }
    }

    /// Points under one isotropic stress with the given strain increments, stepped `steps`
    /// times, each active point's stress changing by `stiffness` times its strain.
    fn run(activation: &mut Activation, dstrain: &[Voigt], steps: usize, stiffness: f64) -> Vec<Vec<Role>> {
        let n = dstrain.len();
        let mut stress = vec![[-1000.0, -1000.0, -1000.0, 0.0, 0.0, 0.0]; n];
        let mut state = vec![0.0; n * STRIDE];
        let mut all = Vec::new();
        for _ in 0..steps {
            let roles = activation.plan(dstrain, &stress, &state, STRIDE);
            for (i, role) in roles.iter().enumerate() {
                if let Role::Steps(de) = role {
                    for k in 0..6 {
                        stress[i][k] += stiffness * de[k];
                    }
                    state[i * STRIDE + state::COORDINATION] = 4.0;
                }
            }
            assert!(activation.complete(&mut stress, &mut state, STRIDE).is_empty());
            all.push(roles);
        }
        all
    }

    #[test]
    fn alike_points_follow_and_different_ones_stay_active() {
        let mut a = Activation::new(tolerances(), 1.0);
        let alike = [-1e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
        let other = [-3e-5, 0.0, 0.0, 0.0, 0.0, 0.0];
        let roles = run(&mut a, &[alike, alike, other, alike], 6, 1e6);
        let last = roles.last().unwrap();
        assert_eq!(last[0], Role::Steps(alike));
        assert_eq!(last[1], Role::Follows(0));
        assert!(matches!(last[2], Role::Steps(_)), "a point straining 30 times faster keeps its RVE: {last:?}");
        assert_eq!(last[3], Role::Follows(0));
        assert_eq!(a.active(), 2);
    }

    /// Two identical points until the second follows the first, then the follower strains 5
    /// times more: within a few steps it is past `refine` (5 % of 1000 Pa is 50 Pa, which 4e-6
    /// of extra strain a step at 1 MPa stiffness crosses in under 13 steps). Returns the strain
    /// it missed while following and the first role it got after leaving.
    fn drift_apart(restart: Restart) -> (f64, Role, Vec<(usize, usize)>, Vec<Voigt>) {
        let mut a = Activation::new(Tolerances { restart, ..tolerances() }, 1.0);
        let de = [-1e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
        let other = [-5e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut stress = vec![[-1000.0, -1000.0, -1000.0, 0.0, 0.0, 0.0]; 2];
        let mut state = vec![0.0; 2 * STRIDE];
        let mut missed = 0.0;
        let mut following = false;
        for _ in 0..40 {
            let second = if following { other } else { de };
            let roles = a.plan(&[de, second], &stress, &state, STRIDE);
            match roles[1] {
                Role::Follows(0) => {
                    following = true;
                    missed += second[0];
                }
                Role::Steps(e) if following => return (missed, Role::Steps(e), Vec::new(), stress),
                _ => {}
            }
            for (i, role) in roles.iter().enumerate() {
                if let Role::Steps(e) = role {
                    stress[i][0] += 1e6 * e[0];
                }
            }
            let copies = a.complete(&mut stress, &mut state, STRIDE);
            if !copies.is_empty() {
                return (missed, roles[1], copies, stress);
            }
        }
        panic!("the drifting follower never became active");
    }

    #[test]
    fn a_drifting_follower_steps_again_from_a_copy_of_its_leader() {
        let (missed, _, copies, stress) = drift_apart(Restart::CopyLeader);
        assert!(missed < 0.0);
        assert_eq!(copies, vec![(0, 1)]);
        assert_eq!(stress[1], stress[0], "the follower takes its copy's stress");
    }

    #[test]
    fn a_drifting_follower_steps_again_with_the_strain_it_missed() {
        let (missed, role, copies, _) = drift_apart(Restart::OwnCaughtUp);
        assert!(copies.is_empty());
        // Its first increment on its own is all it missed plus this step's.
        let Role::Steps(e) = role else { panic!("{role:?}") };
        assert!((e[0] - (missed + -5e-6)).abs() < 1e-18, "caught up {e:?}, missed {missed}");
    }

    #[test]
    fn a_follower_takes_its_leaders_stress_increment_and_its_own_void_ratio() {
        let mut a = Activation::new(tolerances(), 1.0);
        let de = [-1e-6, -1e-6, 0.0, 0.0, 0.0, 0.0];
        run(&mut a, &[de, de], 3, 1e6);
        assert_eq!(a.leaders(), vec![None, Some(0)]);
        let mut stress = vec![[-1000.0, -1000.0, -1000.0, 0.0, 0.0, 0.0], [-1010.0, -1010.0, -1010.0, 0.0, 0.0, 0.0]];
        let mut state = vec![0.0; 2 * STRIDE];
        state[state::VOID_RATIO] = 0.6;
        state[STRIDE + state::VOID_RATIO] = 0.6;
        let roles = a.plan(&[de, de], &stress, &state, STRIDE);
        assert_eq!(roles[1], Role::Follows(0));
        stress[0][0] -= 7.0;
        state[state::COORDINATION] = 4.5;
        assert!(a.complete(&mut stress, &mut state, STRIDE).is_empty());
        assert_eq!(stress[1][0], -1017.0);
        assert_eq!(stress[1][1], -1010.0);
        assert_eq!(state[STRIDE + state::COORDINATION], 4.5);
        let expected = 1.6 * (-2e-6f64).exp() - 1.0;
        assert!((state[STRIDE + state::VOID_RATIO] - expected).abs() < 1e-15);
    }

    #[test]
    fn a_follower_the_leaders_increment_would_put_in_tension_steps_again() {
        let mut a = Activation::new(tolerances(), 1.0);
        let de = [1e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
        run(&mut a, &[de, de], 3, 1e6);
        assert_eq!(a.leaders(), vec![None, Some(0)]);
        // The leader unloads to nearly nothing; the follower, a little less loaded, would end
        // in tension with the same increment.
        let mut stress = vec![[-1000.0, -1000.0, -1000.0, 0.0, 0.0, 0.0], [-990.0, -990.0, -990.0, 0.0, 0.0, 0.0]];
        let mut state = vec![0.0; 2 * STRIDE];
        a.plan(&[de, de], &stress, &state, STRIDE);
        stress[0] = [-0.5, -0.5, -0.5, 0.0, 0.0, 0.0];
        assert_eq!(a.complete(&mut stress, &mut state, STRIDE), vec![(0, 1)]);
        assert_eq!(stress[1], stress[0], "it restarts from a copy of its leader");
        assert_eq!(a.leaders(), vec![None, None]);
    }

    #[test]
    fn removing_a_leader_frees_its_followers() {
        let mut a = Activation::new(tolerances(), 1.0);
        let de = [-1e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
        run(&mut a, &[de, de, de], 4, 1e6);
        assert_eq!(a.leaders(), vec![None, Some(0), Some(0)]);
        a.retain(&[false, true, true]);
        assert_eq!(a.leaders(), vec![None, None]);
        let saved = a.to_json();
        let mut b = Activation::new(tolerances(), 1.0);
        b.load_json(saved).unwrap();
        assert_eq!(b.points, a.points);
    }
}
