//! The candidate pair lists' rebuild: periodic positions wrapped into the cell, spheres
//! numbered in space before the first build, candidates found by the broad phase and merged into
//! the lists (keeping the history of pairs still present).

use crate::dem::broad_phase::{periodic_sphere_pairs, sphere_pairs, wall_pairs, Candidate};
use crate::dem::contacts::{PairList, MAX_HISTORY, MAX_PARAMS};
use crate::dem::pairing::{Other, PairBodies};
use crate::dem::particles::FREE;
use crate::dem::sim::{DemSim, DemWorld, ListsBuilt};
use crate::error::{GraniteError, Result};
use crate::math::{sub3 as sub, Vec3};

/// Most pairs a parallel piece of a rebuild's merge holds (each finds its place in the old list by
/// bisection, so pieces can be small enough for two workers to share the merge evenly).
const MERGE_PIECE: usize = 1024;
/// Most images of a sphere a thin periodic cell may put within reach along one axis.
const MAX_IMAGES_ACROSS: f64 = 64.0;
/// Fewest spheres in a simulation renumbered in space before it first runs.
pub(crate) const MIN_SPHERES_TO_ORDER: usize = 1024;

/// The candidate lists' rebuild, a stage of the step (and of set-up calls that change the
/// lists' reach). Reads the world's spheres, clumps, bodies, walls, cell and laws; writes its
/// pair lists (merged, keeping the history of pairs still present) and, in a periodic cell, the
/// positions brought back into it; records in `built` what the lists were built from. `spare`
/// is storage the merge may fill (kept between rebuilds).
pub(crate) struct Rebuild {
    /// The Verlet skin.
    pub(crate) skin: f64,
    /// Whether the merge may run in parallel pieces (see `DemSim::in_parallel`).
    pub(crate) parallel: bool,
}

impl Rebuild {
    pub(crate) fn run(&self, world: &mut DemWorld, built: &mut ListsBuilt, spare: &mut PairList) -> Result<()> {
        let (p_stride, h_stride) = world.pair_strides();
        if p_stride > MAX_PARAMS || h_stride > MAX_HISTORY {
            return Err(GraniteError::Setup(format!(
                "a contact law uses more than {MAX_PARAMS} parameters or {MAX_HISTORY} history values per contact"
            )));
        }
        world.wrap_into_cell(self.skin)?;
        // Renumbering would leave the bodies' pairs with spheres pointing at others.
        if world.contacts.spheres.is_empty()
            && world.contacts.sphere_walls.is_empty()
            && world.contacts.body_spheres.is_empty()
        {
            world.order_spheres_in_space(self.skin);
        }
        let w = &*world;
        let s = &w.spheres;
        let mut candidates = match &w.cell {
            Some(cell) => periodic_sphere_pairs(&s.x, &s.radius, self.skin, cell),
            None => sphere_pairs(&s.x, &s.radius, self.skin),
        };
        if !w.clumps.is_empty() {
            // Members of one clump never touch each other.
            for block in candidates.iter_mut() {
                block.retain(|&(a, b, _)| {
                    let ca = s.clump[a as usize];
                    ca == FREE || ca != s.clump[b as usize]
                });
            }
        }
        let mut pairs = std::mem::take(&mut world.contacts.spheres);
        let mut wall_list = std::mem::take(&mut world.contacts.sphere_walls);
        let w = &*world;
        let s = &w.spheres;
        let strides = (p_stride, h_stride);
        let mut merge_spheres = || w.merge_pairs(&mut pairs, spare, &candidates, strides, (false, self.parallel));
        let mut find_and_merge_walls = || {
            let wall_candidates = wall_pairs(&s.x, &s.radius, &w.walls, self.skin);
            w.merge_pairs(&mut wall_list, &mut PairList::default(), &wall_candidates, strides, (true, self.parallel))
        };
        // Independent: side by side, the wall search and merge (0.3 ms in the 10k deposition)
        // keep a second worker busy while the sphere pairs' merge starts, and it then takes
        // pieces of that merge.
        let (missing_spheres, missing_walls) = if self.parallel {
            rayon::join(merge_spheres, find_and_merge_walls)
        } else {
            (merge_spheres(), find_and_merge_walls())
        };
        let missing = missing_walls.or(missing_spheres);
        world.contacts.spheres = pairs;
        world.contacts.sphere_walls = wall_list;
        if let Some(pair) = missing {
            return Err(world.missing_law(pair));
        }
        built.x = world.spheres.x.clone();
        built.walls = world.walls.iter().map(|w| w.position).collect();
        built.wall_turns = vec![0.0; world.walls.len()];
        built.h = world.cell.as_ref().map(|c| c.h);
        built.radius_max = world.spheres.largest_radius();
        built.radius_min = world.spheres.smallest_radius();
        world.rebuild_kind_pairs(self.skin)?;
        world.needs_rebuild = false;
        Ok(())
    }
}

impl DemWorld {
    /// Brings periodic positions back into the cell and fixes the shifts of their pairs.
    fn wrap_into_cell(&mut self, skin: f64) -> Result<()> {
        let Some(cell) = &self.cell else { return Ok(()) };
        let k = &self.kinds;
        let widest_body = (0..k.len()).map(|i| k.bounding_radius(i)).fold(0.0, f64::max);
        let reach = 2.0 * self.spheres.largest_radius().max(widest_body) + skin;
        let widths = cell.widths();
        // A thin cell is searched over as many images as the reach spans (see
        // `periodic_sphere_pairs`); one flattened to a sliver of the reach has collapsed.
        if widths.iter().any(|&w| !(w * MAX_IMAGES_ACROSS >= reach)) {
            return Err(GraniteError::Setup(format!(
                "periodic cell collapsed: its widths {widths:?} (between opposite faces) must be at least 1/{MAX_IMAGES_ACROSS} \
                 of the interaction reach {reach:.4e} (largest diameter + skin)"
            )));
        }
        let inv = cell.inverse();
        let offset_of = |x: &Vec3| {
            let s = cell.reduced(&inv, *x);
            [s[0].floor() as i32, s[1].floor() as i32, s[2].floor() as i32]
        };
        let clump_offsets: Vec<[i32; 3]> = self.clumps.x.iter().map(offset_of).collect();
        let offsets: Vec<[i32; 3]> = (0..self.spheres.len())
            .map(|i| match self.spheres.clump[i] {
                FREE => offset_of(&self.spheres.x[i]),
                c => clump_offsets[c as usize],
            })
            .collect();
        let body_offsets: Vec<[i32; 3]> = self.kinds.x.iter().map(offset_of).collect();
        if offsets.iter().chain(&body_offsets).all(|k| *k == [0; 3]) {
            return Ok(());
        }
        for (x, k) in self.kinds.x.iter_mut().zip(&body_offsets) {
            *x = sub(*x, cell.shift_vector(*k));
        }
        // A pair's second body or sphere is seen through the image that keeps it where it was.
        let c = &mut self.contacts;
        for (list, second) in [(&mut c.bodies, &body_offsets), (&mut c.body_spheres, &offsets)] {
            for i in 0..list.len() {
                let (ka, kb) = (body_offsets[list.a[i] as usize], second[list.b[i] as usize]);
                for a in 0..3 {
                    list.shift[i][a] += kb[a] - ka[a];
                }
            }
            list.resort();
        }
        for (x, k) in self.clumps.x.iter_mut().zip(&clump_offsets) {
            let v = cell.shift_vector(*k);
            *x = sub(*x, v);
        }
        for (x, k) in self.spheres.x.iter_mut().zip(&offsets) {
            let v = cell.shift_vector(*k);
            *x = sub(*x, v);
        }
        let p = &mut self.contacts.spheres;
        for i in 0..p.len() {
            let (ka, kb) = (offsets[p.a[i] as usize], offsets[p.b[i] as usize]);
            for a in 0..3 {
                p.shift[i][a] += kb[a] - ka[a];
            }
        }
        p.resort();
        Ok(())
    }

    /// Numbers the spheres slab by slab across the longest side of the domain (then row by row;
    /// under gravity, across the longest side that is not the nearest to it),
    /// so that a parallel piece of spheres, and of the pairs sorted by their first sphere, is a
    /// region of space: its neighbours' data is mostly the piece's own, and stays in that core's
    /// cache. Done only before the first candidate lists exist (no pair to renumber), for systems
    /// large enough to run in several pieces, without clumps. Ids stay with their spheres.
    fn order_spheres_in_space(&mut self, skin: f64) {
        let n = self.spheres.len();
        if n < MIN_SPHERES_TO_ORDER || !self.clumps.is_empty() {
            return;
        }
        let reach = (2.0 * self.spheres.largest_radius() + skin).max(f64::MIN_POSITIVE);
        // Fractional position in the domain on each axis, and the domain's size.
        let (fraction, size): (Vec<Vec3>, Vec3) = match &self.cell {
            Some(cell) => {
                let inv = cell.inverse();
                let s = self.spheres.x.iter().map(|x| cell.reduced(&inv, *x).map(|c| c.rem_euclid(1.0))).collect();
                (s, cell.widths())
            }
            None => {
                let (lo, hi) = crate::math::point_bounds(&self.spheres.x);
                let size = [0, 1, 2].map(|a| (hi[a] - lo[a]).max(f64::MIN_POSITIVE));
                let s = self.spheres.x.iter().map(|x| [0, 1, 2].map(|a| (x[a] - lo[a]) / size[a])).collect();
                (s, size)
            }
        };
        if fraction.iter().flatten().any(|c| !c.is_finite()) {
            return;
        }
        let mut axes = [0, 1, 2];
        axes.sort_by(|&a, &b| size[b].total_cmp(&size[a]));
        // Under gravity the slabs stand along it, the axis nearest to it coming last: a settling
        // heap then puts a share of its bottom, where the contacts are, in every piece, and its
        // force chains, mostly along gravity, within pieces (a pair across pieces costs a store
        // and a gather; see `write_back`).
        let g = self.gravity;
        let down = (0..3).max_by(|&a, &b| g[a].abs().total_cmp(&g[b].abs())).filter(|&a| g[a] != 0.0);
        axes.sort_by_key(|&a| Some(a) == down);
        let cells = size.map(|l| ((l / reach) as u64).clamp(1, 1 << 20));
        let key = |f: &Vec3| axes.map(|a| ((f[a] * cells[a] as f64) as u64).min(cells[a] - 1));
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| key(&fraction[i]));
        self.spheres.permute(&order);
    }

    /// Merges `candidates` into `list` (see `PairList::merge`), giving each new pair the law of
    /// its two materials (the second a wall's if `wall`), in parallel pieces if `parallel`;
    /// returns a pair of materials without a contact law, if it met one.
    fn merge_pairs(
        &self,
        list: &mut PairList,
        spare: &mut PairList,
        candidates: &[Vec<Candidate>],
        strides: (usize, usize),
        (wall, parallel): (bool, bool),
    ) -> Option<(u16, u16)> {
        // Pieces of at most MERGE_PIECE pairs (a periodic search hands over one sorted list).
        let pieces: Vec<&[Candidate]> = candidates.iter().flat_map(|b| b.chunks(MERGE_PIECE)).collect();
        let other = if wall { Other::Walls } else { Other::Same };
        let body = PairBodies { material: &self.spheres.material, other, parallel };
        self.merge_with_laws(list, spare, &pieces, strides, body, |a, b| self.info_for(a, b, wall))
    }
}

impl DemSim {
    /// A new Verlet skin. Candidate lists already built are rebuilt with it now (a state saved
    /// next holds the new, shorter or longer, lists); otherwise the first step builds them.
    pub fn set_skin(&mut self, skin: f64) -> Result<()> {
        if !(skin >= 0.0) {
            return Err(GraniteError::param("skin", skin, "must be >= 0"));
        }
        self.skin = skin;
        if self.world.needs_rebuild {
            return Ok(());
        }
        self.rebuild_candidates()
    }

    /// Rebuilds the candidate pair lists (keeping the history of pairs still present).
    pub fn rebuild_candidates(&mut self) -> Result<()> {
        let stage = Rebuild { skin: self.skin, parallel: self.in_parallel() };
        // An RVE (sequential) rebuilds rarely and is copied into every material point: no spare.
        let mut none = PairList::default();
        let spare = if self.sequential { &mut none } else { &mut self.spare_pairs };
        stage.run(&mut self.world, &mut self.built, spare)?;
        self.rebuilds += 1;
        Ok(())
    }

    /// [`DemWorld::deep_overlaps`] of the set-up as the first step would see it: candidate lists in
    /// force are used as they are, missing ones are built now (the step still builds its own, with
    /// its checks). Empty when the lists cannot be built (the step reports why).
    pub fn deep_overlaps_before_run(&mut self, fraction: f64, most: usize) -> Vec<(String, f64)> {
        if self.world.needs_rebuild {
            if self.rebuild_candidates().is_err() {
                return Vec::new();
            }
            self.world.needs_rebuild = true;
        }
        self.world.deep_overlaps(fraction, most)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_build_numbers_spheres_slab_by_slab_along_the_longest_side() {
        let mut sim = DemSim::new();
        let m = sim.world.add_material("grains", 1000.0).unwrap();
        let (r, spacing) = (0.01, 0.05);
        // 8 x 40 x 4 spheres far apart (no contacts), added from the far end of y backwards.
        let mut placed = Vec::new();
        for j in (0..40).rev() {
            for i in 0..8 {
                for k in 0..4 {
                    placed.push([i as f64 * spacing, j as f64 * spacing, k as f64 * spacing]);
                }
            }
        }
        for x in &placed {
            sim.world.add_sphere(m, *x, r, [0.0; 3]).unwrap();
        }
        let before: std::collections::HashMap<u64, Vec3> =
            sim.world.spheres.id.iter().copied().zip(sim.world.spheres.x.iter().copied()).collect();
        sim.world.set_dt(1e-6).unwrap();
        sim.step().unwrap();
        assert_eq!(sim.world.spheres.len(), placed.len());
        for (id, x) in sim.world.spheres.id.iter().zip(&sim.world.spheres.x) {
            assert_eq!(before[id], *x, "sphere {id} lost its position");
        }
        let y = &sim.world.spheres.x;
        assert!(y.windows(2).all(|w| w[0][1] <= w[1][1]), "not ordered along y, the longest side");
        assert!(y[0][1] == 0.0 && y[y.len() - 1][1] == 39.0 * spacing);
    }
}
