//! The state of a DEM simulation and its set-up operations. The step is in `step.rs`.

use crate::dem::cell::{CellControl, PeriodicCell};
use crate::dem::clump::{mass_properties, Clumps};
use crate::dem::contacts::PairList;
use crate::dem::particles::Spheres;
use crate::dem::walls::Wall;
use crate::error::{GraniteError, Result};
pub use crate::ext::contact::Elastic;
use crate::ext::{ContactLaw, PairInfo};
use crate::math::{add3, scale3, Vec3};
use std::sync::Arc;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DemMaterial {
    pub name: String,
    pub density: f64,
    /// Elastic constants, for laws that take them from the two materials in contact (Hertz's
    /// `E*`); an infinite modulus is a rigid body. None: the law's own values apply.
    #[serde(default)]
    pub elastic: Option<Elastic>,
}

/// The DEM world: the bodies, their contacts, the cell, the walls, the materials and laws, the
/// clock, and what set-up calls changed since the last step (the lists to rebuild, the time step
/// to check). A step reads and writes it through the stages of [`DemSim`]; everything a user sets
/// or measures is here.
#[derive(Clone)]
pub struct DemWorld {
    pub spheres: Spheres,
    pub clumps: Clumps,
    pub walls: Vec<Wall>,
    pub materials: Vec<DemMaterial>,
    pub gravity: Vec3,
    /// A periodic cell, or None for an open domain. Sphere velocities are then the fluctuations
    /// around the cell's affine field `L x`.
    pub cell: Option<PeriodicCell>,
    /// Stress/strain control of the periodic cell, applied before every step.
    pub cell_control: Option<CellControl>,
    /// Cell matrix strains are measured from (set with the cell, reset on demand).
    pub cell_reference: Option<nalgebra::Matrix3<f64>>,
    /// Cundall local damping (applied to the whole acceleration, gravity included, as YADE does).
    pub damping: f64,
    pub dt: f64,
    pub time: f64,
    pub step: u64,
    pub seed: u64,
    /// The contact laws and every candidate pair (of spheres, bodies of plugin kinds and walls)
    /// with its law, parameters and history.
    pub contacts: crate::dem::contact_set::ContactSet,
    /// Lasting external loads on single spheres, by id (see `bodies.rs`).
    pub external: Vec<crate::dem::particles::ExternalLoad>,
    /// Bodies of a plugin kind (potential particles, capsules, ...) and their loads for the
    /// spheres (see `dem::kinds`).
    pub kinds: crate::dem::kinds::KindScene,
    pub events: Vec<String>,
    pub(crate) next_id: u64,
    /// Whether a set-up call changed what the candidate lists were built from (bodies added or
    /// removed, moved by hand, a new cell): the next step rebuilds them.
    pub(crate) needs_rebuild: bool,
    pub(crate) time_step_check: TimeStepCheck,
}

/// Where the check of the time step against the contacts' vibrations stands (see
/// `stability.rs`); set-up calls that change the stability bound reset it.
#[derive(Clone, Debug, Default)]
pub(crate) struct TimeStepCheck {
    /// Whether the time step was found above the bound since it was last set (said once in
    /// `events`).
    pub(crate) warned: bool,
    /// Step of the last check; None: check after the next contact stage (new simulation, time
    /// step or damping).
    pub(crate) last: Option<u64>,
}

impl TimeStepCheck {
    /// Whether a step is to check its contacts: the first after a reset, then one that follows
    /// a rebuild at least `CHECK_EVERY` steps after the last check (the contact network changes
    /// little between rebuilds).
    pub(crate) fn due(&self, rebuilt: bool, step: u64) -> bool {
        match self.last {
            None => true,
            Some(at) => rebuilt && step >= at + crate::dem::stability::CHECK_EVERY,
        }
    }
}

/// What the candidate lists were built from: the next step compares the spheres, walls and cell
/// with it to know whether the lists still hold (see `step.rs`).
#[derive(Clone, Debug)]
pub(crate) struct ListsBuilt {
    /// Sphere and wall positions.
    pub(crate) x: Vec<Vec3>,
    pub(crate) walls: Vec<Vec3>,
    /// Cell matrix.
    pub(crate) h: Option<nalgebra::Matrix3<f64>>,
    /// Largest and smallest sphere radii (radii change only through calls that ask for a
    /// rebuild).
    pub(crate) radius_max: f64,
    pub(crate) radius_min: f64,
    /// The angle each wall has turned since (rad).
    pub(crate) wall_turns: Vec<f64>,
}

impl ListsBuilt {
    /// The sphere farthest from where the lists saw it (its place then carried by the cell's
    /// deformation since, `h h0⁻¹`, in a periodic cell) and that distance; None without spheres.
    pub(crate) fn farthest_moved(&self, x: &[Vec3], cell: Option<&nalgebra::Matrix3<f64>>) -> Option<(usize, f64)> {
        let f = match (cell, &self.h) {
            (Some(h), Some(h0)) => h * h0.try_inverse().unwrap_or_else(nalgebra::Matrix3::identity),
            _ => nalgebra::Matrix3::identity(),
        };
        x.iter()
            .zip(&self.x)
            .map(|(x, x0)| {
                let reference = f * nalgebra::Vector3::from(*x0);
                (0..3).map(|a| (x[a] - reference[a]).powi(2)).sum::<f64>().sqrt()
            })
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }
}

impl Default for ListsBuilt {
    fn default() -> Self {
        ListsBuilt {
            x: Vec::new(),
            walls: Vec::new(),
            h: None,
            radius_max: 0.0,
            radius_min: f64::INFINITY,
            wall_turns: Vec::new(),
        }
    }
}

/// A DEM simulation: the [`DemWorld`] and the step's pipeline of stages (`step.rs`) with what
/// they keep between steps (the broad phase's settings and what it last built from, the parallel
/// pieces, the energy tracker).
#[derive(Clone)]
pub struct DemSim {
    pub world: DemWorld,
    /// Verlet skin: extra distance within which pairs are kept as candidates.
    pub skin: f64,
    /// Run every stage on the calling thread (an RVE inside a parallel loop over material points).
    pub sequential: bool,
    /// Whether a time step proved above the contacts' stability limit stops the run (else it is
    /// only said, once).
    pub stop_on_unstable_dt: bool,
    /// Number of candidate-list rebuilds so far.
    pub rebuilds: u64,
    /// The energy balance, when tracked (see `energy.rs`).
    pub energy: Option<crate::dem::energy::EnergyTracker>,
    pub(crate) built: ListsBuilt,
    /// Storage the next rebuild of `pairs` fills (the previous list's; see `PairList::merge`).
    pub(crate) spare_pairs: PairList,
    /// Where the parallel stages cut the pair lists (found again after a rebuild).
    pub(crate) piece_bounds: crate::dem::pieces::PieceBounds,
    /// What each parallel contact piece leaves for the gather (see `Handover`).
    pub(crate) handovers: crate::dem::contact_stage::Handovers,
}

impl Default for DemSim {
    fn default() -> Self {
        Self::new()
    }
}

impl Default for DemWorld {
    fn default() -> Self {
        Self::new()
    }
}

impl DemSim {
    pub fn new() -> DemSim {
        DemSim {
            world: DemWorld::new(),
            skin: 0.0,
            sequential: false,
            stop_on_unstable_dt: true,
            rebuilds: 0,
            energy: None,
            built: ListsBuilt::default(),
            spare_pairs: PairList::default(),
            piece_bounds: Default::default(),
            handovers: Default::default(),
        }
    }
}

impl DemWorld {
    pub fn new() -> DemWorld {
        DemWorld {
            spheres: Spheres::default(),
            clumps: Clumps::default(),
            walls: Vec::new(),
            materials: Vec::new(),
            gravity: [0.0; 3],
            cell: None,
            cell_control: None,
            cell_reference: None,
            damping: 0.0,
            dt: 0.0,
            time: 0.0,
            step: 0,
            seed: 0,
            contacts: Default::default(),
            external: Vec::new(),
            kinds: Default::default(),
            events: Vec::new(),
            next_id: 0,
            needs_rebuild: true,
            time_step_check: TimeStepCheck::default(),
        }
    }

    pub fn add_material(&mut self, name: &str, density: f64) -> Result<u16> {
        if !(density > 0.0 && density.is_finite()) {
            return Err(GraniteError::param_in(format!("`density` of material \"{name}\""), density, "must be > 0"));
        }
        if self.materials.len() >= u16::MAX as usize {
            return Err(GraniteError::Setup("too many materials".into()));
        }
        self.materials.push(DemMaterial { name: name.into(), density, elastic: None });
        Ok((self.materials.len() - 1) as u16)
    }

    /// Gives material `m` elastic constants (a modulus of infinity: rigid), for contact laws
    /// that combine the two materials of a pair. Contacts already made take them at once.
    pub fn set_material_elastic(&mut self, m: u16, elastic: Option<Elastic>) -> Result<()> {
        if let Some(e) = elastic {
            if !(e.young > 0.0) || e.young.is_nan() {
                return Err(GraniteError::param("young", e.young, "must be > 0 (inf: rigid)"));
            }
            if !(0.0..0.5).contains(&e.poisson) {
                return Err(GraniteError::param("poisson", e.poisson, "must lie in [0, 0.5)"));
            }
        }
        let material = self
            .materials
            .get_mut(m as usize)
            .ok_or_else(|| GraniteError::Setup(format!("no material with index {m}")))?;
        material.elastic = elastic;
        let laws = self.contacts.laws.clone();
        self.refresh_pair_laws(&laws);
        self.recheck_time_step();
        Ok(())
    }

    /// The id the next sphere gets.
    pub fn next_sphere_id(&self) -> u64 {
        self.next_id
    }

    /// Uses `law` for contacts between materials `a` and `b` (either order), or for every pair
    /// without a law of its own when `pair` is None, from the next step on. Contacts that exist
    /// keep their history (tangential spring, rolling...) when their law stays of the same kind,
    /// and get their parameters from the new law; a contact whose law changes kind starts afresh.
    pub fn set_contact_law(&mut self, law: Box<dyn ContactLaw>, pair: Option<(u16, u16)>) -> Result<()> {
        if let Some((a, b)) = pair {
            for m in [a, b] {
                if m as usize >= self.materials.len() {
                    return Err(GraniteError::Setup(format!("no material with index {m}")));
                }
            }
        }
        use crate::dem::contacts::{MAX_HISTORY, MAX_PARAMS};
        if law.param_count() > MAX_PARAMS || law.history_count() > MAX_HISTORY {
            return Err(GraniteError::Setup(format!(
                "contact law `{}` uses more than {MAX_PARAMS} parameters or {MAX_HISTORY} history values per contact",
                law.name()
            )));
        }
        let old_laws = self.contacts.laws.clone();
        let key = pair.map(|(a, b)| (a.min(b), a.max(b)));
        let current = match key {
            Some(k) => self.contacts.law_of.get(&k).copied(),
            None => self.contacts.default_law,
        };
        let users = |idx: u16| {
            self.contacts.law_of.values().filter(|&&v| v == idx).count()
                + usize::from(self.contacts.default_law == Some(idx))
        };
        // A law of this key alone is replaced where it is; one shared (split off by a change of
        // one pair's parameters) stays for the others.
        let idx = match current {
            Some(idx) if users(idx) == 1 => {
                self.contacts.laws[idx as usize] = Arc::from(law);
                idx
            }
            _ => {
                if self.contacts.laws.len() >= u16::MAX as usize {
                    return Err(GraniteError::Setup("too many contact laws".into()));
                }
                self.contacts.laws.push(Arc::from(law));
                (self.contacts.laws.len() - 1) as u16
            }
        };
        match key {
            Some(k) => {
                self.contacts.law_of.insert(k, idx);
            }
            None => self.contacts.default_law = Some(idx),
        }
        self.refresh_pair_laws(&old_laws);
        self.recheck_time_step();
        Ok(())
    }

    pub fn add_sphere(&mut self, material: u16, x: Vec3, radius: f64, v: Vec3) -> Result<usize> {
        let density = self.check_sphere(material, x, radius, v)?;
        self.spheres.push(self.next_id, x, radius, density, material, v);
        self.next_id += 1;
        self.needs_rebuild = true;
        Ok(self.spheres.len() - 1)
    }

    /// A sphere a step can move: finite position and velocity, a radius whose mass at the
    /// material's density is finite and > 0. Returns that density.
    pub(crate) fn check_sphere(&self, material: u16, x: Vec3, radius: f64, v: Vec3) -> Result<f64> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(GraniteError::param("radius", radius, "must be > 0"));
        }
        if x.iter().any(|c| !c.is_finite()) {
            return Err(GraniteError::param("position", format!("{x:?}"), "must be finite"));
        }
        if v.iter().any(|c| !c.is_finite()) {
            return Err(GraniteError::param("velocity", format!("{v:?}"), "must be finite"));
        }
        let density = self
            .materials
            .get(material as usize)
            .ok_or_else(|| GraniteError::Setup(format!("no material with index {material}")))?
            .density;
        let mass = crate::dem::particles::sphere_mass(density, radius);
        if !(mass.is_finite() && mass > 0.0) {
            return Err(GraniteError::param(
                "radius",
                radius,
                &format!("gives a mass of {mass:e} kg at density {density:e} kg/m^3: it must be finite and > 0"),
            ));
        }
        Ok(density)
    }

    /// Makes the domain periodic with the given cell (or open again with None).
    pub fn set_cell(&mut self, cell: Option<PeriodicCell>) {
        self.cell_reference = cell.as_ref().map(|c| c.h);
        self.cell = cell;
        // Pairs with an image are keyed by a shift of the old cell.
        for list in [&mut self.contacts.spheres, &mut self.contacts.bodies, &mut self.contacts.body_spheres] {
            *list = PairList::default();
        }
        self.needs_rebuild = true;
    }

    /// Forces a rebuild of the candidate lists at the next step (after moving particles by hand).
    pub fn needs_rebuild_for_tests(&mut self) {
        self.needs_rebuild = true;
    }

    /// Logarithmic strain of the cell since its reference state: `ln(|a_i| / |a_i,0|)` along each
    /// base vector and the volumetric strain `ln(V / V_0)`.
    pub fn cell_strain(&self) -> Option<([f64; 3], f64)> {
        let (cell, h0) = (self.cell.as_ref()?, self.cell_reference.as_ref()?);
        let axial = [0, 1, 2].map(|a| (cell.h.column(a).norm() / h0.column(a).norm()).ln());
        Some((axial, (cell.volume() / h0.determinant().abs()).ln()))
    }

    /// Volume of solid: free spheres, the union volume of each clump and the free bodies of
    /// plugin kinds (fixed ones are container parts).
    pub fn solid_volume(&self) -> f64 {
        let s = &self.spheres;
        let free: f64 = (0..s.len())
            .filter(|&i| s.clump[i] == crate::dem::particles::FREE)
            .map(|i| 4.0 / 3.0 * std::f64::consts::PI * s.radius[i].powi(3))
            .sum();
        let k = &self.kinds;
        let bodies: f64 = (0..k.len()).filter(|&i| !k.fixed[i]).map(|i| k.shapes[k.shape[i] as usize].volume()).sum();
        free + self.clumps.volume.iter().sum::<f64>() + bodies
    }

    /// Void ratio of the periodic cell (thesis 5.15): `(V_cell - V_particles) / V_particles`.
    pub fn void_ratio(&self) -> Option<f64> {
        let v = self.cell_volume()?;
        let vp = self.solid_volume();
        Some((v - vp) / vp)
    }

    /// Volume the packing occupies for stress measures: the periodic cell's, if any.
    pub fn cell_volume(&self) -> Option<f64> {
        self.cell.as_ref().map(|c| c.volume())
    }

    pub fn add_wall(&mut self, wall: Wall) -> usize {
        self.walls.push(wall);
        self.needs_rebuild = true;
        self.walls.len() - 1
    }

    /// Adds a clump of spheres `(centre, radius)` (world coordinates) of one material. Mass and
    /// inertia come from the union of the members (voxels at `resolution` per axis when they
    /// overlap). Returns the clump index.
    pub fn add_clump(&mut self, material: u16, members: &[(Vec3, f64)], v: Vec3, resolution: usize) -> Result<usize> {
        let density = self
            .materials
            .get(material as usize)
            .ok_or_else(|| GraniteError::Setup(format!("no material with index {material}")))?
            .density;
        let props = mass_properties(members, density, resolution)?;
        let c = self.add_clump_with(material, members, &props)?;
        self.clumps.v[c] = v;
        Ok(c)
    }

    /// Adds a clump whose mass properties are already known (a template computed once, then
    /// moved with [`crate::dem::clump::MassProperties::transformed`]).
    pub fn add_clump_with(
        &mut self,
        material: u16,
        members: &[(Vec3, f64)],
        props: &crate::dem::clump::MassProperties,
    ) -> Result<usize> {
        // Everything is checked before the first member goes in: a refused clump leaves no
        // loose spheres behind.
        props.check()?;
        for (x, r) in members {
            self.check_sphere(material, *x, *r, [0.0; 3])?;
        }
        let props = *props;
        let v = [0.0; 3];
        let first = self.spheres.len();
        for (x, r) in members {
            self.add_sphere(material, *x, *r, v)?;
        }
        let clump = self.clumps.len() as u32;
        let ids: Vec<u32> = (first..self.spheres.len()).map(|i| i as u32).collect();
        for &i in &ids {
            // Contacts of a member see the whole clump's mass (restitution, time step).
            self.spheres.mass[i as usize] = props.mass;
            self.spheres.clump[i as usize] = clump;
        }
        let positions: Vec<Vec3> = members.iter().map(|(x, _)| *x).collect();
        self.clumps.push(&ids, &positions, &props);
        Ok(self.clumps.len() - 1)
    }

    /// Removes spheres by mask (and the contacts they were in). A clump goes as a whole when any
    /// of its members is removed.
    pub fn remove_spheres(&mut self, keep: &[bool]) {
        let mut keep = keep.to_vec();
        if !self.clumps.is_empty() {
            let mut keep_clump = vec![true; self.clumps.len()];
            for (i, &k) in keep.iter().enumerate() {
                let c = self.spheres.clump[i];
                if !k && c != crate::dem::particles::FREE {
                    keep_clump[c as usize] = false;
                }
            }
            for (i, k) in keep.iter_mut().enumerate() {
                let c = self.spheres.clump[i];
                if c != crate::dem::particles::FREE && !keep_clump[c as usize] {
                    *k = false;
                }
            }
            // New sphere indices after compaction, then the clumps that remain.
            let new_index = crate::dem::particles::compacted_indices(&keep);
            let old = std::mem::take(&mut self.clumps);
            let mut new_clump = vec![u32::MAX; old.len()];
            for c in 0..old.len() {
                if !keep_clump[c] {
                    continue;
                }
                new_clump[c] = self.clumps.len() as u32;
                if self.clumps.start.is_empty() {
                    self.clumps.start.push(0);
                }
                for m in old.members_of(c) {
                    self.clumps.members.push(new_index[old.members[m] as usize]);
                    self.clumps.local.push(old.local[m]);
                }
                self.clumps.start.push(self.clumps.members.len() as u32);
                self.clumps.x.push(old.x[c]);
                self.clumps.v.push(old.v[c]);
                self.clumps.w.push(old.w[c]);
                self.clumps.q.push(old.q[c]);
                self.clumps.mass.push(old.mass[c]);
                self.clumps.inertia.push(old.inertia[c]);
                self.clumps.volume.push(old.volume[c]);
                self.clumps.force.push(old.force[c]);
                self.clumps.torque.push(old.torque[c]);
            }
            for c in self.spheres.clump.iter_mut() {
                if *c != crate::dem::particles::FREE {
                    *c = new_clump[*c as usize];
                }
            }
        }
        let gone: Vec<u64> = (0..keep.len()).filter(|&i| !keep[i]).map(|i| self.spheres.id[i]).collect();
        self.external.retain(|l| !gone.contains(&l.id));
        self.spheres.retain(&keep);
        // Contacts between spheres that stay keep their history.
        self.contacts.spheres.retain_spheres(&keep, true);
        self.contacts.sphere_walls.retain_spheres(&keep, false);
        // The bodies' pairs with spheres name them by index: found again at the next rebuild,
        // their contacts starting afresh.
        self.contacts.body_spheres = Default::default();
        self.needs_rebuild = true;
    }

    /// Force the spheres and bodies exert on wall `w` in the last step: the opposite of the forces of its
    /// pairs, summed in pair order. Worked out when asked (a pass over the wall pairs), not at
    /// every step, where it was a serial pass of 8 us in a step of the 10k-sphere deposition
    /// that any number of threads waited for. Zero for a wall index out of range.
    pub fn wall_force(&self, w: usize) -> Vec3 {
        [&self.contacts.sphere_walls, &self.contacts.body_walls].into_iter().fold([0.0; 3], |sum, pairs| {
            pairs
                .b
                .iter()
                .zip(&pairs.force)
                .filter(|(&b, _)| b as usize == w)
                .fold(sum, |sum, (_, f)| add3(sum, scale3(*f, -1.0)))
        })
    }

    /// [`DemWorld::wall_force`] of every wall, in one pass over the pairs.
    pub fn wall_forces(&self) -> Vec<Vec3> {
        let mut forces = vec![[0.0; 3]; self.walls.len()];
        for pairs in [&self.contacts.sphere_walls, &self.contacts.body_walls] {
            for (&b, f) in pairs.b.iter().zip(&pairs.force) {
                if let Some(sum) = forces.get_mut(b as usize) {
                    *sum = add3(*sum, scale3(*f, -1.0));
                }
            }
        }
        forces
    }

    /// The torque about `about` of the forces the spheres and bodies exerted on `walls` in the
    /// last step, each at its contact point (found again where the spheres are now).
    pub fn wall_torque(&self, walls: &[usize], about: Vec3) -> Vec3 {
        let mut on = vec![false; self.walls.len()];
        for &w in walls {
            if let Some(flag) = on.get_mut(w) {
                *flag = true;
            }
        }
        let mut torque = [0.0; 3];
        let mut add = |point: Vec3, f: Vec3| {
            let arm = crate::math::sub3(point, about);
            torque = add3(torque, crate::math::cross3(arm, scale3(f, -1.0)));
        };
        let p = &self.contacts.sphere_walls;
        for k in (0..p.len()).filter(|&k| p.touching[k] && on[p.b[k] as usize]) {
            let (i, w) = (p.a[k] as usize, p.b[k] as usize);
            if let Some(c) = self.walls[w].contact(self.spheres.x[i], self.spheres.radius[i], f64::INFINITY) {
                add(c.point, p.force[k]);
            }
        }
        let (list, touches) = (&self.contacts.body_walls, &self.contacts.body_touches[1]);
        for &(c, point) in touches {
            if on[list.b[c.slot] as usize] {
                add(point, list.force[c.slot]);
            }
        }
        torque
    }

    /// Largest stable time step estimate: `min sqrt(m / k_n)` over one-contact oscillators of
    /// each sphere (and each free body of a plugin kind) with a copy of itself and with each wall
    /// (multiply by ~0.2-0.3 for packings).
    pub fn critical_dt(&self) -> Option<f64> {
        let mut best: Option<f64> = None;
        let mut consider = |law: Option<u16>, info: PairInfo| {
            if let Some(l) = law {
                let k = self.contacts.laws[l as usize].max_normal_stiffness(&info);
                if k > 0.0 {
                    let dt = (info.effective_mass() / k).sqrt();
                    best = Some(best.map_or(dt, |b: f64| b.min(dt)));
                }
            }
        };
        for i in 0..self.spheres.len() {
            let mi = self.spheres.material[i];
            let mut self_pair = self.pair_info(i, Some(i));
            self_pair.seed = 0;
            consider(self.law_for(mi, mi), self_pair);
            for (w, wall) in self.walls.iter().enumerate() {
                consider(self.law_for(mi, wall.material), self.info_for(i, w, true));
            }
        }
        let k = &self.kinds;
        for i in (0..k.len()).filter(|&i| !k.fixed[i]) {
            let mi = k.material[i];
            let mut self_pair = self.kind_info(i, i, crate::dem::pairing::Other::Same);
            self_pair.seed = 0;
            consider(self.law_for(mi, mi), self_pair);
            for (w, wall) in self.walls.iter().enumerate() {
                consider(self.law_for(mi, wall.material), self.kind_info(i, w, crate::dem::pairing::Other::Walls));
            }
        }
        best
    }

    pub fn set_dt(&mut self, dt: f64) -> Result<()> {
        self.dt = crate::params::time_step(dt)?;
        self.recheck_time_step();
        Ok(())
    }

    /// Whether `dt` is within `critical_dt` of the spheres and laws present (a script's `sim.dt`
    /// checks it at once; a run checks it again, as spheres and laws may come later).
    pub fn check_dt(&self, dt: f64) -> Result<()> {
        crate::params::time_step_within(dt, self.critical_dt(), "sqrt(m/k_n) of the stiffest, lightest contact")
    }

    /// Cundall damping (YADE's), in [0, 1).
    pub fn set_damping(&mut self, damping: f64) -> Result<()> {
        if !(0.0..1.0).contains(&damping) {
            return Err(GraniteError::param("damping", damping, "Cundall damping must be in [0, 1)"));
        }
        self.damping = damping;
        // It enters the stability bound.
        self.recheck_time_step();
        Ok(())
    }

    /// Has the time step checked against the contacts' limit after the next contact stage, and
    /// said again if above it.
    pub(crate) fn recheck_time_step(&mut self) {
        self.time_step_check = TimeStepCheck::default();
    }

    /// Where the time-step check stands (for a device that steps this world): the step of the
    /// last check (None: check after the next contact stage), and whether it was said.
    pub fn time_step_check_state(&self) -> (Option<u64>, bool) {
        (self.time_step_check.last, self.time_step_check.warned)
    }

    pub fn set_time_step_check_state(&mut self, last: Option<u64>, warned: bool) {
        self.time_step_check = TimeStepCheck { last, warned };
    }

    /// Asks each law whether it can make the contacts it may meet: between the materials of the
    /// spheres, and between those and the walls' materials.
    fn check_pairs_of_materials(&self) -> Result<()> {
        let mut sphere_materials: Vec<u16> = self.spheres.material.clone();
        sphere_materials.sort_unstable();
        sphere_materials.dedup();
        let mut wall_materials: Vec<u16> = self.walls.iter().map(|w| w.material).collect();
        wall_materials.sort_unstable();
        wall_materials.dedup();
        let elastic = |m: u16| self.materials.get(m as usize).and_then(|m| m.elastic);
        let name = |m: u16| self.materials.get(m as usize).map_or(String::new(), |m| m.name.clone());
        for &a in &sphere_materials {
            let others =
                sphere_materials.iter().map(|&b| (b, 1.0)).chain(wall_materials.iter().map(|&w| (w, f64::INFINITY)));
            for (b, r2) in others {
                let Some(law) = self.law_for(a, b) else { continue };
                let info = PairInfo { radius: [1.0, r2], mass: [1.0, r2], seed: 0, elastic: [elastic(a), elastic(b)] };
                let law = &self.contacts.laws[law as usize];
                law.check_pair(&info).map_err(|why| {
                    GraniteError::Setup(format!(
                        "contact law `{}` between materials \"{}\" and \"{}\"{}: {why}",
                        law.name(),
                        name(a),
                        name(b),
                        if r2.is_infinite() { " (a wall)" } else { "" }
                    ))
                })?;
            }
        }
        Ok(())
    }

    pub fn validate(&self) -> Result<()> {
        crate::params::require_time_step(self.dt)?;
        if !self.spheres.is_empty() && self.contacts.laws.is_empty() {
            return Err(GraniteError::Setup("no contact law: call contact_law(...) before running".into()));
        }
        self.check_pairs_of_materials()?;
        self.check_dt(self.dt)?;
        if !(0.0..1.0).contains(&self.damping) {
            return Err(GraniteError::param("damping", self.damping, "must be in [0, 1)"));
        }
        Ok(())
    }
}

/// What the candidate lists were built from: an engine that steps a simulation elsewhere (an RVE
/// on a GPU) takes it along and gives it back, so that the lists are rebuilt when this engine
/// would have rebuilt them.
#[derive(Debug, Clone, PartialEq)]
pub struct VerletState {
    pub x_at_build: Vec<Vec3>,
    pub h_at_build: Option<nalgebra::Matrix3<f64>>,
    pub needs_rebuild: bool,
    pub rebuilds: u64,
}

impl DemSim {
    /// Approximate memory held by this simulation's arrays, in bytes.
    pub fn memory_bytes(&self) -> usize {
        let s = &self.world.spheres;
        let per_sphere = std::mem::size_of::<u64>()
            + 6 * std::mem::size_of::<Vec3>()
            + 3 * std::mem::size_of::<f64>()
            + std::mem::size_of::<u16>()
            + std::mem::size_of::<u8>()
            + std::mem::size_of::<u32>();
        s.x.capacity() * per_sphere
            + self.built.x.capacity() * 24
            + self.world.contacts.memory_bytes()
            + crate::dem::contact_set::list_bytes(&self.spare_pairs)
            + self.piece_bounds.bytes()
            + self.handovers.bytes()
            + self.world.clumps.len() * 200
            + self.world.kinds.memory_bytes()
    }

    /// Whether the world can be stepped: a time step within the contacts' stability bound, a
    /// contact law for every pair of materials that may meet, damping in [0, 1), a skin >= 0.
    pub fn validate(&self) -> Result<()> {
        self.world.validate()?;
        if !(self.skin >= 0.0) {
            return Err(GraniteError::param("skin", self.skin, "must be >= 0"));
        }
        Ok(())
    }

    pub fn verlet_state(&self) -> VerletState {
        VerletState {
            x_at_build: self.built.x.clone(),
            h_at_build: self.built.h,
            needs_rebuild: self.world.needs_rebuild || self.built.x.len() != self.world.spheres.len(),
            rebuilds: self.rebuilds,
        }
    }

    /// Takes back the state of lists built elsewhere (with the spheres' radii as they are).
    pub fn set_verlet_state(&mut self, state: VerletState) {
        self.world.needs_rebuild = state.needs_rebuild || state.x_at_build.len() != self.world.spheres.len();
        self.built.x = state.x_at_build;
        self.built.h = state.h_at_build;
        self.rebuilds = state.rebuilds;
        self.built.radius_max = self.world.spheres.largest_radius();
        self.built.radius_min = self.world.spheres.smallest_radius();
    }
}
