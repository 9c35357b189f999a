//! The potential particles' part of a DEM step: candidate pairs (their bounding spheres in the
//! broad phase), contact detection per pair from its previous solution, the contact law of the
//! two materials (any registered law: geometry and law are apart), forces summed per particle in
//! pair order, and rigid-body motion.
//!
//! Detection runs pair by pair in parallel, each pair writing only its own values; the law calls
//! and the sums then run in pair order, so results do not depend on the number of threads.

use super::contact::{detect, detect_plane, Solution, Touch};
use crate::dem::broad_phase::{sphere_pairs, wall_pairs, Candidate};
use crate::dem::contacts::PairList;
use crate::dem::motion::RigidMotion;
use crate::dem::pairing::{Other, PairBodies};
use crate::dem::rigid::{laws_in_pair_order, move_rigid_bodies, LawContact, RigidSet};
use crate::dem::sim::DemSim;
use crate::dem::walls::WallShape;
use crate::error::{GraniteError, Result};
use crate::math::{add3, cross3, sub3, Vec3};
use rayon::prelude::*;

/// History values a pair keeps after its law's: the last solution of its contact problem (a
/// point and, between two particles, the weight `lambda`), whether there is one, and the two
/// parts of the last overlap.
const WARM: usize = 7;

/// A touching pair's geometry and relative motion, as its law takes them.
#[derive(Debug, Clone, Copy)]
struct Found {
    touch: Touch,
    rel_velocity: Vec3,
    rel_spin: Vec3,
}

impl DemSim {
    /// Touching contacts of the potential particles (with one another and with walls).
    pub fn potential_contact_count(&self) -> usize {
        self.potential_pairs.touching_count() + self.potential_wall_pairs.touching_count()
    }

    /// Values per pair of the potential particles' lists: the laws' then [`WARM`].
    fn potential_strides(&self) -> (usize, usize) {
        let (p, h) = self.pair_strides();
        (p, h + WARM)
    }

    /// The Verlet skin of the potential particles: the simulation's, or a tenth of the smallest
    /// bounding radius when none is set.
    pub(crate) fn potential_skin(&self) -> f64 {
        if self.skin > 0.0 {
            return self.skin;
        }
        0.1 * self.potentials.bounding_radii().into_iter().fold(f64::INFINITY, f64::min)
    }

    /// Rebuilds the potential particles' candidate lists (pairs still present keep their
    /// history and warm starts). Called with the spheres' rebuild.
    pub(crate) fn rebuild_potential_pairs(&mut self) -> Result<()> {
        if self.potentials.is_empty() {
            return Ok(());
        }
        if self.cell.is_some() {
            return Err(GraniteError::Setup("potential particles run in open domains, not in a periodic cell".into()));
        }
        if let Some(w) = self.walls.iter().find(|w| !matches!(w.shape, WallShape::Plane { .. })) {
            return Err(GraniteError::Setup(format!(
                "wall \"{}\": potential particles meet plane walls (wall_plane, box_walls) and one another; build other \
                 container parts from potential particles (potential_box)",
                w.name
            )));
        }
        let radii = self.potentials.bounding_radii();
        let skin = self.potential_skin();
        let strides = self.potential_strides();
        let mut pairs = sphere_pairs(&self.potentials.x, &radii, skin);
        let mut walls = wall_pairs(&self.potentials.x, &radii, &self.walls, skin);
        // Fixed particles (container parts) are moved, not pushed: their contacts with one
        // another and with walls would change nothing.
        let fixed = &self.potentials.fixed;
        pairs.iter_mut().for_each(|block| block.retain(|&(a, b, _)| !(fixed[a as usize] && fixed[b as usize])));
        walls.iter_mut().for_each(|block| block.retain(|&(a, _, _)| !fixed[a as usize]));
        let mut list = std::mem::take(&mut self.potential_pairs);
        let mut wall_list = std::mem::take(&mut self.potential_wall_pairs);
        let missing = self.merge_potential(&mut list, &pairs, strides, false).or(self.merge_potential(
            &mut wall_list,
            &walls,
            strides,
            true,
        ));
        self.potential_pairs = list;
        self.potential_wall_pairs = wall_list;
        if let Some(pair) = missing {
            return Err(self.missing_law(pair));
        }
        self.potential_x_at_build = self.potentials.x.clone();
        Ok(())
    }

    /// Merges candidates into a list, giving new pairs their law and parameters; returns a pair
    /// of materials without a law, if it met one.
    fn merge_potential(
        &self,
        list: &mut PairList,
        candidates: &[Vec<Candidate>],
        strides: (usize, usize),
        wall: bool,
    ) -> Option<(u16, u16)> {
        let pieces: Vec<&[Candidate]> = candidates.iter().map(|b| &b[..]).collect();
        let other = if wall { Other::Walls } else { Other::Same };
        let bodies = PairBodies { material: &self.potentials.material, other, parallel: false };
        self.merge_with_laws(list, &mut PairList::default(), &pieces, strides, bodies, |a, b| {
            self.potential_info(a, b, wall)
        })
    }

    /// Contacts, forces and motion of the potential particles for one step; returns the largest
    /// distance a particle's centre moved since the lists were built.
    pub(crate) fn potential_step(&mut self, motion: &RigidMotion) -> Result<f64> {
        let p = &mut self.potentials;
        p.place_all();
        p.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        p.torque.iter_mut().for_each(|t| *t = [0.0; 3]);
        let hs = self.potential_strides().1;
        let own = hs - WARM;
        let pairs = std::mem::take(&mut self.potential_pairs);
        let walls = std::mem::take(&mut self.potential_wall_pairs);
        let result = self.potential_contacts(pairs, own, false).and_then(|pairs| {
            self.potential_pairs = pairs;
            self.potential_contacts(walls, own, true)
        });
        match result {
            Ok(walls) => self.potential_wall_pairs = walls,
            Err(e) => {
                // A list that failed is gone: a later step finds its pairs again.
                self.needs_rebuild = true;
                return Err(e);
            }
        }
        let p = &mut self.potentials;
        let set = RigidSet {
            x: &mut p.x,
            v: &mut p.v,
            w: &mut p.w,
            q: &mut p.q,
            mass: &p.mass,
            inertia: &p.inertia,
            fixed: &p.fixed,
            force: &p.force,
            torque: &p.torque,
        };
        let moved = move_rigid_bodies(set, &self.potential_x_at_build, motion).map_err(|i| GraniteError::Unstable {
            step: self.step,
            time: self.time,
            reason: format!(
                "non-finite position or velocity of potential particle {} (x = {:?}, v = {:?}); the time step may be too large",
                p.id[i], p.x[i], p.v[i]
            ),
        })?;
        Ok(moved)
    }

    /// Detects the contacts of a list (pairs of particles, or particle-wall pairs), runs their
    /// laws and adds the forces to the particles, in pair order. Returns the list.
    fn potential_contacts(&mut self, mut list: PairList, own: usize, wall: bool) -> Result<PairList> {
        let started = std::time::Instant::now();
        let hs = list.history_stride;
        let p = &self.potentials;
        let placed = &p.placed;
        let walls = &self.walls;
        let (a_list, b_list) = (&list.a, &list.b);
        // Each pair's detection, from its own warm start, in parallel.
        let found: Vec<std::result::Result<Option<Found>, String>> = list
            .history
            .par_chunks_mut(hs.max(1))
            .enumerate()
            .map(|(k, history)| {
                let (i, j) = (a_list[k] as usize, b_list[k] as usize);
                let warm = &mut history[own..own + WARM];
                let start = (warm[4] == 1.0).then(|| Solution {
                    point: [warm[0], warm[1], warm[2]],
                    lambda: warm[3],
                    depths: [warm[5], warm[6]],
                });
                let a = &placed[i];
                let touch = if wall {
                    let w = &walls[j];
                    let WallShape::Plane { normal } = w.shape else { return Ok(None) };
                    // Clear of the plane by more than the bounding radius: no solve.
                    let height = (0..3).map(|c| normal[c] * (a.position[c] - w.position[c])).sum::<f64>();
                    if height > a.bounding_radius {
                        return Ok(None);
                    }
                    let (deepest, touch) = detect_plane(a, w.position, normal, start.map(|s| s.point))
                        .map_err(|e| format!("potential particle {} and wall \"{}\": {e}", p.id[i], w.name))?;
                    warm[..3].copy_from_slice(&deepest);
                    warm[4] = 1.0;
                    touch.map(|t| (t, w.velocity, [0.0; 3], [0.0; 3]))
                } else {
                    let b = &placed[j];
                    // Bounding spheres apart: no solve (the warm start waits for the next touch).
                    let d = sub3(b.position, a.position);
                    let reach = a.bounding_radius + b.bounding_radius;
                    if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > reach * reach
                        || a.clear_of(b.position, b.bounding_radius)
                        || b.clear_of(a.position, a.bounding_radius)
                    {
                        return Ok(None);
                    }
                    let found = detect(a, b, start)
                        .map_err(|e| format!("potential particles {} and {}: {e}", p.id[i], p.id[j]))?;
                    warm[..3].copy_from_slice(&found.solution.point);
                    warm[3] = found.solution.lambda;
                    warm[4] = 1.0;
                    warm[5..7].copy_from_slice(&found.solution.depths);
                    found.touch.map(|t| (t, p.v[j], p.w[j], p.x[j]))
                };
                Ok(touch.map(|(touch, vj, wj, xj)| {
                    let at = |v: Vec3, w: Vec3, x: Vec3| add3(v, cross3(w, sub3(touch.point, x)));
                    let rel_velocity = if wall {
                        sub3(vj, at(p.v[i], p.w[i], p.x[i]))
                    } else {
                        sub3(at(vj, wj, xj), at(p.v[i], p.w[i], p.x[i]))
                    };
                    Found { touch, rel_velocity, rel_spin: sub3(wj, p.w[i]) }
                }))
            })
            .collect();
        let detected = std::time::Instant::now();
        self.potential_seconds[0] += (detected - started).as_secs_f64();
        let mut touching = Vec::new();
        for (k, f) in found.into_iter().enumerate() {
            match f {
                Ok(Some(found)) => touching.push((k, found)),
                Ok(None) => {
                    if list.touching[k] {
                        // Apart: the law's history starts again at the next touch.
                        list.touching[k] = false;
                        list.force[k] = [0.0; 3];
                        list.history[k * hs..k * hs + own].iter_mut().for_each(|h| *h = 0.0);
                    }
                }
                Err(reason) => {
                    return Err(GraniteError::Unstable {
                        step: self.step,
                        time: self.time,
                        reason: format!(
                        "the contact problem of {reason}; the particles may overlap too deeply: lower the time step"
                    ),
                    })
                }
            }
        }
        // Each law on its contacts, in pair order.
        let contacts: Vec<LawContact> = touching
            .iter()
            .map(|(k, f)| LawContact {
                slot: *k,
                normal: f.touch.normal,
                overlap: f.touch.overlap,
                rel_velocity: f.rel_velocity,
                rel_spin: f.rel_spin,
            })
            .collect();
        let (force, moment) = laws_in_pair_order(&self.laws, &mut list, &contacts, self.dt);
        // Sums in pair order.
        let p = &mut self.potentials;
        for (e, (k, found)) in touching.iter().enumerate() {
            let (i, j) = (list.a[*k] as usize, list.b[*k] as usize);
            let (f, m, point) = (force[e], moment[e], found.touch.point);
            list.touching[*k] = true;
            list.force[*k] = f;
            p.force[i] = add3(p.force[i], f);
            p.torque[i] = add3(p.torque[i], add3(cross3(sub3(point, p.x[i]), f), m));
            if !wall {
                let back = [-f[0], -f[1], -f[2]];
                p.force[j] = add3(p.force[j], back);
                p.torque[j] = sub3(add3(p.torque[j], cross3(sub3(point, p.x[j]), back)), m);
            }
        }
        self.potential_seconds[1] += detected.elapsed().as_secs_f64();
        Ok(list)
    }
}
