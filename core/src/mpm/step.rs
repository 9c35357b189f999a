//! One MPM time step, thesis eqs. 3.10-3.42, as stages called in a fixed order. Each stage is a
//! free function whose signature shows what it reads and what it writes.

use crate::error::{GraniteError, Result};
use crate::ext::{G2pBatch, LawBatch, VelocityUpdate};
use crate::math::{rotate_by_spin, strain_rate_from_gradient, Mat3, Vec3, Voigt};
use crate::mpm::boundary::{Boundary, PointLoad};
use crate::mpm::grid::{scatter, Grid, NodeSums, SlabIndex};
use crate::mpm::mesh::{Location, Mesh};
use crate::mpm::points::Points;
use crate::mpm::shape::{
    first_plane, node_offsets, Basis, CubicBspline, Gimp, Linear, QuadraticBspline, ShapeFunction, Tensor, Weights,
    MAX_NODES,
};
use crate::mpm::sim::{Material, MpmSim, OutOfMeshPolicy, ShapeFunctions, StressRate, StressScheme, VolumetricStrain};
use rayon::prelude::*;

/// Points handled per task (and per velocity-update call).
const CHUNK: usize = 256;
/// Fewest points or nodes worth handing to another thread: below this, waking a worker costs more
/// than the work (small scenes then run on one thread with no synchronisation at all).
const MIN_PER_TASK: usize = 4096;
const MIN_CHUNKS_PER_TASK: usize = MIN_PER_TASK / CHUNK;
/// Nodes lighter than this fraction of the lightest point are treated as empty.
const MASS_EPS: f64 = 1e-12;

/// Calls `$sim.$method::<S>()` with the shape functions `S` of the simulation's choice and mesh.
macro_rules! with_shape_functions {
    ($sim:expr, $method:ident) => {
        match ($sim.shape, $sim.mesh.dim) {
            (ShapeFunctions::Linear, 3) => $sim.$method::<Tensor<Linear, 3>>(),
            (ShapeFunctions::Linear, _) => $sim.$method::<Tensor<Linear, 2>>(),
            (ShapeFunctions::Gimp { .. }, 3) => $sim.$method::<Tensor<Gimp, 3>>(),
            (ShapeFunctions::Gimp { .. }, _) => $sim.$method::<Tensor<Gimp, 2>>(),
            (ShapeFunctions::QuadraticBspline, 3) => $sim.$method::<Tensor<QuadraticBspline, 3>>(),
            (ShapeFunctions::QuadraticBspline, _) => $sim.$method::<Tensor<QuadraticBspline, 2>>(),
            (ShapeFunctions::CubicBspline, 3) => $sim.$method::<Tensor<CubicBspline, 3>>(),
            (ShapeFunctions::CubicBspline, _) => $sim.$method::<Tensor<CubicBspline, 2>>(),
        }
    };
}

impl MpmSim {
    /// Advances the simulation by one time step.
    pub fn step(&mut self) -> Result<()> {
        with_shape_functions!(self, step_with)
    }

    /// Locates the points and sorts them into slabs for the scatter.
    fn place<S: ShapeFunction>(&mut self) -> Result<()> {
        self.shape.check(&self.mesh)?;
        locate(&self.mesh, &self.points, &mut self.loc)?;
        self.grid.resize(self.mesh.node_count());
        let (mesh, loc) = (&self.mesh, &self.loc);
        self.slabs.build(mesh, S::SPAN, loc.len(), |p| first_plane::<S>(mesh, loc[p].t));
        Ok(())
    }

    fn step_with<S: ShapeFunction>(&mut self) -> Result<()> {
        let dt = self.dt;
        let t_next = self.time + dt;
        self.place::<S>()?;
        self.locate_point_loads();
        let affine = self.velocity_update.affine();
        let centre_volume = self.volumetric_strain == VolumetricStrain::CellCentre;
        let at = Placement::of(&self.mesh, &self.loc, self.shape, self.volumetric_strain);
        let grid = &mut self.grid;
        let pts = &mut self.points;
        let (slabs, bc, g) = (&self.slabs, &self.boundary, self.gravity);
        let strategy = self.velocity_update.as_ref();
        let turn = self.stress_rate == StressRate::Jaumann;
        if centre_volume && !S::Basis::VOLUME_AT_CELL_CENTRE {
            return Err(GraniteError::param(
                "volumetric_strain",
                "\"cell\"",
                "\"cell\" with linear shape functions only (these are not); \"point\" with any",
            ));
        }
        let kin = Kinematics { turn, centre_volume };
        match self.scheme {
            StressScheme::Usl => {
                p2g::<S>(grid, &at, slabs, pts, g, affine, Maps::MassMomentumForce);
                grid_velocity(grid, bc, self.time);
                point_loads::<S>(grid, &at, pts, &bc.point_loads, self.time);
                grid_update(grid, bc, self.damping, dt, self.time);
                g2p::<S>(pts, grid, &at, strategy, dt, Some(kin));
                stress_update(pts, &mut self.materials)?;
            }
            StressScheme::Usf => {
                p2g::<S>(grid, &at, slabs, pts, g, affine, Maps::MassMomentum);
                grid_velocity(grid, bc, self.time);
                strain_update::<S>(pts, &grid.velocity, &at, dt, kin);
                stress_update(pts, &mut self.materials)?;
                p2g::<S>(grid, &at, slabs, pts, g, affine, Maps::Force);
                point_loads::<S>(grid, &at, pts, &bc.point_loads, self.time);
                grid_update(grid, bc, self.damping, dt, self.time);
                g2p::<S>(pts, grid, &at, strategy, dt, None);
            }
            StressScheme::Musl => {
                p2g::<S>(grid, &at, slabs, pts, g, affine, Maps::MassMomentumForce);
                grid_velocity(grid, bc, self.time);
                point_loads::<S>(grid, &at, pts, &bc.point_loads, self.time);
                grid_update(grid, bc, self.damping, dt, self.time);
                g2p::<S>(pts, grid, &at, strategy, dt, None);
                // Remap the updated point momentum (positions as at the start of the step).
                p2g::<S>(grid, &at, slabs, pts, g, affine, Maps::Momentum);
                grid_velocity(grid, bc, t_next);
                strain_update::<S>(pts, &grid.velocity, &at, dt, kin);
                stress_update(pts, &mut self.materials)?;
            }
        }
        self.time = t_next;
        self.step += 1;
        for m in &self.materials {
            for e in m.law.point_objects().map(|o| o.take_events()).unwrap_or_default() {
                self.events.push(format!("step {} (t = {:.6e} s), material \"{}\": {e}", self.step, self.time, m.name));
            }
        }
        self.check_stable()?;
        self.say_unloaded_nodes();
        self.say_flung_points();
        self.handle_out_of_mesh()
    }

    /// No part of a solid body outruns the P waves of its own material: points that move faster
    /// than their material's wave speed have been flung (a load on nodes that lost their
    /// material, a time step too large, a law gone wrong), however the run goes on. Said once.
    fn say_flung_points(&mut self) {
        if self.flung_said {
            return;
        }
        let speeds: Vec<Option<f64>> = self.materials.iter().map(|m| m.law.wave_speed(m.density)).collect();
        let p = &self.points;
        let (count, fastest) = (0..p.len())
            .into_par_iter()
            .with_min_len(MIN_PER_TASK)
            .filter_map(|i| {
                let c = speeds[p.material[i] as usize]?;
                let v2 = p.v[i].iter().map(|x| x * x).sum::<f64>();
                (v2 > c * c).then_some((1usize, (v2, i, c)))
            })
            .reduce(
                || (0, (0.0, 0, 0.0)),
                |a, b| (a.0 + b.0, if b.1 .0 > a.1 .0 || (b.1 .0 == a.1 .0 && b.1 .1 < a.1 .1) { b.1 } else { a.1 }),
            );
        if count == 0 {
            return;
        }
        self.flung_said = true;
        let (v2, i, c) = fastest;
        let v = v2.sqrt();
        self.events.push(format!(
            "step {} (t = {:.6e} s): {count} material point(s) move faster than their material's P-wave speed, \
             point {} at {v:.4e} m/s against {c:.4e} m/s: they are flung, not flowing (a load on grid nodes that \
             lost their material, a time step too large, a law out of its range); said once",
            self.step, self.time, p.id[i]
        ));
    }

    /// A nodal load (a traction on a face or a mesh group) acts on nodes fixed in space: once the
    /// material has moved away from some of them, their share of the load is lost (a node with no
    /// mass takes no force), and the points near a loaded node left with little mass are flung.
    /// Said once a load, with the cure.
    fn say_unloaded_nodes(&mut self) {
        for (k, f) in self.boundary.forces.iter().enumerate() {
            if self.unloaded_said.contains(&k) || f.factor.at(self.time) == 0.0 {
                continue;
            }
            let empty = f
                .nodes
                .iter()
                .zip(&f.force)
                .filter(|(&n, force)| {
                    **force != [0.0; 3] && self.grid.sums.get(n as usize).is_none_or(|s| s.mass <= MASS_EPS)
                })
                .count();
            if empty > 0 {
                self.unloaded_said.push(k);
                self.events.push(format!(
                    "step {} (t = {:.6e} s): {empty} of the {} nodes of nodal load {k} (a traction or force on grid \
                     nodes) have no material left under them, and their share of the load is lost; a load that \
                     follows the material is carried by points: sim.point_traction(...) or sim.point_pressure(...)",
                    self.step,
                    self.time,
                    f.nodes.len()
                ));
            }
        }
    }

    /// Maps the points' mass, momentum and forces to the grid (eqs. 3.17, 3.18, 3.21, 3.23) without
    /// advancing time, and returns the nodal sums: for inspection and conservation checks.
    pub fn map_to_grid(&mut self) -> Result<&[NodeSums]> {
        with_shape_functions!(self, map_with)?;
        Ok(&self.grid.sums)
    }

    fn map_with<S: ShapeFunction>(&mut self) -> Result<()> {
        self.place::<S>()?;
        let affine = self.velocity_update.affine();
        let at = Placement::of(&self.mesh, &self.loc, self.shape, self.volumetric_strain);
        p2g::<S>(&mut self.grid, &at, &self.slabs, &self.points, self.gravity, affine, Maps::MassMomentumForce);
        Ok(())
    }

    /// Stops a run whose points stopped being finite, or move faster than a cell per step: past
    /// that speed the CFL condition `dt (c + |v|) < h` fails whatever the wave speed `c`, the
    /// point skips over grid nodes, and a stable run never gets there.
    fn check_stable(&self) -> Result<()> {
        let p = &self.points;
        let cell = self.mesh.min_cell();
        let fastest2 = (cell / self.dt).powi(2);
        let speed2 = |i: usize| p.v[i].iter().map(|c| c * c).sum::<f64>();
        let finite = |i: usize| {
            p.x[i].iter().all(|c| c.is_finite())
                && p.v[i].iter().all(|c| c.is_finite())
                && p.stress[i].iter().all(|c| c.is_finite())
        };
        let bad =
            (0..p.len()).into_par_iter().with_min_len(MIN_PER_TASK).find_first(|&i| !finite(i) || speed2(i) > fastest2);
        let Some(i) = bad else { return Ok(()) };
        let reason = if finite(i) {
            let speed = speed2(i).sqrt();
            format!(
                "material point {} moves at {speed:.4e} m/s, {:.4e} m in one step of {:.4e} s: more than a cell \
                 ({cell:.4e} m), which breaks the CFL condition dt (c + |v|) < h; the run has blown up or the time \
                 step is too large for this motion",
                p.id[i],
                speed * self.dt,
                self.dt
            )
        } else {
            format!(
                "non-finite value at material point {} (position {:?}, velocity {:?}, stress {:?}); \
                 try a smaller time step or a more dissipative velocity update",
                p.id[i], p.x[i], p.v[i], p.stress[i]
            )
        };
        Err(GraniteError::Unstable { step: self.step, time: self.time, reason })
    }

    /// A point that leaves the mesh faster than the CFL condition `dt (c + |v|) < h` allows has
    /// not flowed out: the run has blown up, and deleting the point would hide it.
    fn left_too_fast(&self, keep: &[bool]) -> Option<String> {
        let h = self.mesh.min_cell();
        // critical_dt() is h / c_p of the fastest material.
        let c = self.critical_dt().map_or(0.0, |dt| h / dt);
        let limit = (h / self.dt - c).max(0.0);
        let p = &self.points;
        let speed = |i: usize| p.v[i].iter().map(|x| x * x).sum::<f64>().sqrt();
        let i = (0..keep.len()).find(|&i| !keep[i] && speed(i) > limit)?;
        Some(format!(
            "material point {} left the mesh at {:.4e} m/s, above the CFL limit h/dt - c_p = {limit:.4e} m/s \
             (h = {h:.4e} m, dt = {:.4e} s, c_p = {c:.4e} m/s): the run has blown up (a smaller time step or a \
             more dissipative velocity update may help)",
            p.id[i],
            speed(i),
            self.dt
        ))
    }

    fn handle_out_of_mesh(&mut self) -> Result<()> {
        let mesh = &self.mesh;
        let keep: Vec<bool> = self.points.x.par_iter().map(|x| mesh.contains(*x)).collect();
        let lost = keep.iter().filter(|k| !**k).count();
        if lost == 0 {
            return Ok(());
        }
        let first = keep.iter().position(|k| !*k).unwrap_or(0);
        if let Some(reason) = self.left_too_fast(&keep) {
            return Err(GraniteError::Unstable { step: self.step, time: self.time, reason });
        }
        let what = format!(
            "{lost} material point(s) left the mesh (first: point {} at {:?})",
            self.points.id[first], self.points.x[first]
        );
        match self.out_of_mesh {
            OutOfMeshPolicy::Stop => Err(GraniteError::Unstable { step: self.step, time: self.time, reason: what }),
            OutOfMeshPolicy::Delete => {
                self.remove_points(&keep);
                self.deleted_points += lost as u64;
                self.events.push(format!("step {} (t = {:.6e} s): {what}; deleted", self.step, self.time));
                Ok(())
            }
        }
    }
}

/// Cell and local coordinates of every point (eq. 3.10).
fn locate(mesh: &Mesh, points: &Points, loc: &mut Vec<Location>) -> Result<()> {
    loc.resize(points.len(), Location { t: [0.0; 3] });
    let outside = loc
        .par_iter_mut()
        .zip(points.x.par_iter())
        .with_min_len(MIN_PER_TASK)
        .map(|(l, x)| match mesh.locate(*x) {
            Some(found) => {
                *l = found;
                0usize
            }
            None => 1,
        })
        .sum::<usize>();
    if outside > 0 {
        return Err(GraniteError::Setup(format!("{outside} material point(s) are outside the mesh")));
    }
    Ok(())
}

/// Where the points are, and what the shape functions need besides.
struct Placement<'a> {
    mesh: &'a Mesh,
    loc: &'a [Location],
    /// GIMP's half point length in cells per axis.
    half: Vec3,
    /// The volumetric strain is taken at the cells' centres (B-bar, linear functions only).
    centre_volume: bool,
}

impl<'a> Placement<'a> {
    /// Where the points are (after `place`), and what the shape functions need besides.
    fn of(mesh: &'a Mesh, loc: &'a [Location], shape: ShapeFunctions, volumetric: VolumetricStrain) -> Placement<'a> {
        Placement {
            mesh,
            loc,
            half: shape.half_in_cells(mesh),
            centre_volume: volumetric == VolumetricStrain::CellCentre,
        }
    }

    /// Weights of point `p`, and the index of its window's first node.
    #[inline(always)]
    fn weights<S: ShapeFunction>(&self, p: usize, w: &mut Weights) -> usize {
        S::eval(self.loc[p].t, self.mesh, self.half, w);
        self.mesh.node_index(w.first)
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Maps {
    MassMomentumForce,
    MassMomentum,
    Momentum,
    Force,
}

/// Particle-to-grid transfer: mass (3.17), momentum (3.18, with the APIC affine term when asked),
/// gravity (3.21) and internal force (3.23) from the points' current stress.
fn p2g<S: ShapeFunction>(
    grid: &mut Grid,
    at: &Placement,
    slabs: &SlabIndex,
    pts: &Points,
    gravity: Vec3,
    affine: bool,
    maps: Maps,
) {
    let (do_mass, do_momentum, do_force) = match maps {
        Maps::MassMomentumForce => (true, true, true),
        Maps::MassMomentum => (true, true, false),
        Maps::Momentum => (false, true, false),
        Maps::Force => (false, false, true),
    };
    grid.sums.par_iter_mut().with_min_len(MIN_PER_TASK).for_each(|s| {
        if do_mass {
            s.mass = 0.0;
        }
        if do_momentum {
            s.momentum = [0.0; 3];
        }
        if do_force {
            s.force = [0.0; 3];
        }
    });
    let off = node_offsets::<S>(at.mesh);
    // B-bar: a point's strain rate takes its volumetric part at the cell's centre, so the
    // internal force must too (the force is the work of the stress on that strain rate): with
    // `m` the mean of the in-plane normal stresses, `f_I = -V (σ ∇N_I(x_p) + m (∇N_I(c) − ∇N_I(x_p)))`.
    // A force from the point's own gradient alone does work the strain does not store, which
    // fed energy into columns that should settle.
    let dn_centre = (at.centre_volume && S::Basis::VOLUME_AT_CELL_CENTRE).then(|| centre_gradients::<S>(at.mesh));
    scatter(&mut grid.sums, at.mesh, slabs, |p, window: &mut [NodeSums], first, w| {
        let base = at.weights::<S>(p, w) - first;
        let m = pts.mass[p];
        let v = pts.v[p];
        let c = &pts.affine[p];
        let s = &pts.stress[p];
        let vol = pts.volume[p];
        // The mean of the in-plane normal stresses, for the B-bar term.
        let mean = s[..S::DIM].iter().sum::<f64>() / S::DIM as f64;
        for k in 0..S::NODES {
            let node = &mut window[base + off[k]];
            let n = w.n[k];
            if do_mass {
                node.mass += m * n;
            }
            if do_momentum {
                let mut vk = v;
                if affine {
                    let d = w.d[k];
                    for a in 0..3 {
                        vk[a] += c[3 * a] * d[0] + c[3 * a + 1] * d[1] + c[3 * a + 2] * d[2];
                    }
                }
                for a in 0..3 {
                    node.momentum[a] += m * n * vk[a];
                }
            }
            if do_force {
                let g = w.dn[k];
                node.force[0] += m * n * gravity[0] - vol * (s[0] * g[0] + s[3] * g[1] + s[5] * g[2]);
                node.force[1] += m * n * gravity[1] - vol * (s[3] * g[0] + s[1] * g[1] + s[4] * g[2]);
                node.force[2] += m * n * gravity[2] - vol * (s[5] * g[0] + s[4] * g[1] + s[2] * g[2]);
                if let Some(dc) = &dn_centre {
                    for a in 0..S::DIM {
                        node.force[a] -= vol * mean * (dc[k][a] - g[a]);
                    }
                }
            }
        }
    });
}

/// The loads carried by points (`PointLoad`) added to the nodal forces through each point's shape
/// functions, as its weight is: the nodal shares of a point's force sum to it (the shape
/// functions sum to 1), so the grid feels the whole load wherever the point is. A few points
/// (one layer under a surface): serial, in a fixed order.
fn point_loads<S: ShapeFunction>(grid: &mut Grid, at: &Placement, pts: &Points, loads: &[PointLoad], t: f64) {
    let off = node_offsets::<S>(at.mesh);
    let mut w = Weights::default();
    for load in loads {
        let factor = load.factor.at(t);
        for (&p, f) in load.at.iter().zip(&load.force) {
            debug_assert!(p < pts.len());
            let base = at.weights::<S>(p, &mut w);
            for k in 0..S::NODES {
                let node = &mut grid.sums[base + off[k]];
                for a in 0..3 {
                    node.force[a] += w.n[k] * factor * f[a];
                }
            }
        }
    }
}

/// Nodal velocity from momentum (eq. 3.18), then velocity constraints (eq. 3.19) at time `t`.
fn grid_velocity(grid: &mut Grid, bc: &Boundary, t: f64) {
    grid.velocity.par_iter_mut().zip(grid.sums.par_iter()).with_min_len(MIN_PER_TASK).for_each(|(v, s)| {
        *v = if s.mass > MASS_EPS {
            [s.momentum[0] / s.mass, s.momentum[1] / s.mass, s.momentum[2] / s.mass]
        } else {
            [0.0; 3]
        };
    });
    for c in &bc.velocity {
        let value = c.value.at(t);
        for &n in &c.nodes {
            grid.velocity[n as usize][c.axis] = value;
        }
    }
}

#[inline]
fn sign_or_zero(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Equation of motion on the nodes: total force (3.25), Cundall damping (3.24, 3.26), explicit
/// update (3.27), friction and velocity constraints; then the effective acceleration.
fn grid_update(grid: &mut Grid, bc: &Boundary, damping: f64, dt: f64, t: f64) {
    for f in &bc.forces {
        let factor = f.factor.at(t);
        for (&n, force) in f.nodes.iter().zip(&f.force) {
            let s = &mut grid.sums[n as usize];
            for a in 0..3 {
                s.force[a] += factor * force[a];
            }
        }
    }
    grid.velocity_new
        .par_iter_mut()
        .zip(grid.sums.par_iter().zip(grid.velocity.par_iter()))
        .with_min_len(MIN_PER_TASK)
        .for_each(|(vn, (s, v))| {
            if s.mass > MASS_EPS {
                let f = s.force;
                let fnorm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
                for a in 0..3 {
                    let acc = (f[a] - damping * fnorm * sign_or_zero(v[a])) / s.mass;
                    vn[a] = v[a] + acc * dt;
                }
            } else {
                *vn = [0.0; 3];
            }
        });
    for fc in &bc.friction {
        for &n in &fc.nodes {
            let n = n as usize;
            if grid.sums[n].mass <= MASS_EPS {
                continue;
            }
            let vn = &mut grid.velocity_new[n];
            let into_wall = fc.sign * vn[fc.axis];
            if into_wall <= 0.0 {
                continue;
            }
            vn[fc.axis] = 0.0;
            let speed_t = (vn[0] * vn[0] + vn[1] * vn[1] + vn[2] * vn[2]).sqrt();
            if speed_t > 0.0 {
                let scale = (speed_t - fc.mu * into_wall).max(0.0) / speed_t;
                for a in 0..3 {
                    vn[a] *= scale;
                }
            }
        }
    }
    for c in &bc.velocity {
        let value = c.value.at(t);
        for &n in &c.nodes {
            grid.velocity_new[n as usize][c.axis] = value;
        }
    }
    let inv_dt = 1.0 / dt;
    grid.accel
        .par_iter_mut()
        .zip(grid.velocity_new.par_iter().zip(grid.velocity.par_iter()))
        .with_min_len(MIN_PER_TASK)
        .for_each(|(a, (vn, v))| {
            *a = [(vn[0] - v[0]) * inv_dt, (vn[1] - v[1]) * inv_dt, (vn[2] - v[2]) * inv_dt];
        });
}

/// Velocity gradient `L_ab = sum_i v_i,a dN_i/dx_b` at a point.
#[inline(always)]
fn velocity_gradient<S: ShapeFunction>(vel: &[Vec3], base: usize, off: &[usize; MAX_NODES], dn: &[Vec3]) -> Mat3 {
    let mut l = [0.0; 9];
    for k in 0..S::NODES {
        let v = vel[base + off[k]];
        let g = dn[k];
        for a in 0..3 {
            l[3 * a] += v[a] * g[0];
            l[3 * a + 1] += v[a] * g[1];
            l[3 * a + 2] += v[a] * g[2];
        }
    }
    l
}

/// APIC's affine matrix `C_p = B_p D_p^-1`, `B_p = sum_i N_i v_i d_i^T` (Jiang et al. 2015), with
/// `D_p` diagonal for a tensor-product basis; an axis without spread (2D's z) gets no column.
#[inline(always)]
fn affine_from_moments<S: ShapeFunction>(vel: &[Vec3], base: usize, off: &[usize; MAX_NODES], w: &Weights) -> Mat3 {
    let mut c = [0.0; 9];
    for k in 0..S::NODES {
        let v = vel[base + off[k]];
        let (n, d) = (w.n[k], w.d[k]);
        for a in 0..3 {
            for b in 0..3 {
                c[3 * a + b] += n * v[a] * d[b];
            }
        }
    }
    for b in 0..3 {
        let inv = if w.moment[b] > 0.0 { 1.0 / w.moment[b] } else { 0.0 };
        for a in 0..3 {
            c[3 * a + b] *= inv;
        }
    }
    c
}

/// How a velocity gradient becomes a strain increment: the stress turned with the spin first
/// (Jaumann), the volumetric part from the cell's centre (B-bar).
#[derive(Clone, Copy)]
struct Kinematics {
    turn: bool,
    centre_volume: bool,
}

/// Strain increment (3.36-3.38) and volume update (3.39-3.40) of one point from a nodal velocity;
/// with `kin.turn`, the stress is turned by the point's spin (the Jaumann rate) before the law
/// adds to it.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn apply_strain<S: ShapeFunction>(
    kin: Kinematics,
    l: &Mat3,
    vel: &[Vec3],
    base: usize,
    off: &[usize; MAX_NODES],
    dn_centre: &[Vec3; MAX_NODES],
    dt: f64,
    dstrain: &mut Voigt,
    strain: &mut Voigt,
    volume: &mut f64,
    turn: Option<&mut Voigt>,
) {
    if let Some(stress) = turn {
        rotate_by_spin(stress, l, dt);
    }
    let mut rate = strain_rate_from_gradient(l);
    let divergence = if S::Basis::VOLUME_AT_CELL_CENTRE {
        let lc = velocity_gradient::<S>(vel, base, off, dn_centre);
        lc[0] + lc[4] + lc[8]
    } else {
        l[0] + l[4] + l[8]
    };
    if kin.centre_volume {
        // The point's own volumetric rate replaced by the centre's, shared by the normal rates of
        // the mesh's axes (plane strain keeps its zero out-of-plane rate).
        let shift = (divergence - (l[0] + l[4] + l[8])) / S::DIM as f64;
        for r in rate.iter_mut().take(S::DIM) {
            *r += shift;
        }
    }
    for c in 0..6 {
        dstrain[c] = rate[c] * dt;
        strain[c] += dstrain[c];
    }
    *volume *= 1.0 + dt * divergence;
}

/// Gradients at the centre of a cell, relative to its lower corner node (linear functions).
fn centre_gradients<S: ShapeFunction>(mesh: &Mesh) -> [Vec3; MAX_NODES] {
    let mut w = Weights::default();
    if S::Basis::VOLUME_AT_CELL_CENTRE {
        S::eval([0.5, 0.5, if S::DIM == 3 { 0.5 } else { 0.0 }], mesh, [0.0; 3], &mut w);
    }
    w.dn
}

/// Strain and volume update from a nodal velocity field (USF: V^i, MUSL: remapped velocity).
fn strain_update<S: ShapeFunction>(pts: &mut Points, vel: &[Vec3], at: &Placement, dt: f64, kin: Kinematics) {
    let off = node_offsets::<S>(at.mesh);
    let dn0 = centre_gradients::<S>(at.mesh);
    (
        pts.dstrain.par_chunks_mut(CHUNK),
        pts.strain.par_chunks_mut(CHUNK),
        pts.volume.par_chunks_mut(CHUNK),
        pts.stress.par_chunks_mut(CHUNK),
    )
        .into_par_iter()
        .enumerate()
        .with_min_len(MIN_CHUNKS_PER_TASK)
        .for_each(|(j, (de, e, vol, stress))| {
            let mut w = Weights::default();
            for p in 0..de.len() {
                let base = at.weights::<S>(j * CHUNK + p, &mut w);
                let lg = velocity_gradient::<S>(vel, base, &off, &w.dn);
                let turned = kin.turn.then_some(&mut stress[p]);
                apply_strain::<S>(kin, &lg, vel, base, &off, &dn0, dt, &mut de[p], &mut e[p], &mut vol[p], turned);
            }
        });
}

/// Grid-to-particle transfer (3.28-3.34 through the velocity-update strategy) and, for USL
/// (`strain` is `Some(turn)`), the strain from the updated grid velocity.
fn g2p<S: ShapeFunction>(
    pts: &mut Points,
    grid: &Grid,
    at: &Placement,
    strategy: &dyn VelocityUpdate,
    dt: f64,
    strain: Option<Kinematics>,
) {
    let with_strain = strain.is_some();
    let kin = strain.unwrap_or(Kinematics { turn: false, centre_volume: false });
    let off = node_offsets::<S>(at.mesh);
    let dn0 = centre_gradients::<S>(at.mesh);
    let affine = strategy.affine();
    let need_gradient = (affine && !S::Basis::AFFINE_FROM_MOMENTS) || with_strain;
    let (vel, acc) = (&grid.velocity_new, &grid.accel);
    (
        pts.x.par_chunks_mut(CHUNK),
        pts.v.par_chunks_mut(CHUNK),
        pts.affine.par_chunks_mut(CHUNK),
        pts.dstrain.par_chunks_mut(CHUNK),
        pts.strain.par_chunks_mut(CHUNK),
        pts.volume.par_chunks_mut(CHUNK),
        pts.stress.par_chunks_mut(CHUNK),
    )
        .into_par_iter()
        .enumerate()
        .with_min_len(MIN_CHUNKS_PER_TASK)
        .for_each(|(j, (x, v, c, de, e, vol, stress))| {
            let len = x.len();
            let mut w = Weights::default();
            let mut v_pic = [[0.0; 3]; CHUNK];
            let mut dv = [[0.0; 3]; CHUNK];
            let mut v_new = [[0.0; 3]; CHUNK];
            let mut v_move = [[0.0; 3]; CHUNK];
            for p in 0..len {
                let base = at.weights::<S>(j * CHUNK + p, &mut w);
                let (mut vp, mut dvp) = ([0.0; 3], [0.0; 3]);
                for k in 0..S::NODES {
                    let i = base + off[k];
                    for a in 0..3 {
                        vp[a] += vel[i][a] * w.n[k];
                        dvp[a] += acc[i][a] * w.n[k];
                    }
                }
                v_pic[p] = vp;
                dv[p] = [dvp[0] * dt, dvp[1] * dt, dvp[2] * dt];
                if affine && S::Basis::AFFINE_FROM_MOMENTS {
                    c[p] = affine_from_moments::<S>(vel, base, &off, &w);
                }
                if need_gradient {
                    let lg = velocity_gradient::<S>(vel, base, &off, &w.dn);
                    if affine && !S::Basis::AFFINE_FROM_MOMENTS {
                        c[p] = lg;
                    }
                    if with_strain {
                        let turned = kin.turn.then_some(&mut stress[p]);
                        apply_strain::<S>(
                            kin,
                            &lg,
                            vel,
                            base,
                            &off,
                            &dn0,
                            dt,
                            &mut de[p],
                            &mut e[p],
                            &mut vol[p],
                            turned,
                        );
                    }
                }
            }
            strategy.update(G2pBatch {
                v_old: v,
                v_pic: &v_pic[..len],
                dv_grid: &dv[..len],
                strain: e,
                v_new: &mut v_new[..len],
                v_move: &mut v_move[..len],
            });
            for p in 0..len {
                for a in 0..3 {
                    x[p][a] += v_move[p][a] * dt;
                }
                v[p] = v_new[p];
            }
        });
}

/// Constitutive update (3.41-3.42): each material's law over its contiguous block of points.
fn stress_update(pts: &mut Points, materials: &mut [Material]) -> Result<()> {
    let mut start = 0;
    for m in materials.iter_mut() {
        let range = start..start + m.count;
        start += m.count;
        if range.is_empty() {
            continue;
        }
        let stride = m.law.state_names().len();
        let law = m.law.as_ref();
        let objects = law.point_objects();
        if let (Some(spread), Some(objects)) = (m.spread.as_mut(), objects) {
            let (stress, dstrain) = (&mut pts.stress[range.clone()], &pts.dstrain[range]);
            spread
                .update(law, stress, dstrain, &mut m.state, stride)
                .and_then(|()| objects.complete_update(stress, &mut m.state))
                .and_then(|copies| spread.copy_objects(objects, &copies))
                .map_err(|e| GraniteError::Other(format!("material \"{}\" ({}): {e}", m.name, law.name())))?;
            continue;
        }
        // Laws with per-point objects (an RVE per point) are expensive per point: one task each.
        let (chunk, min_chunks) = if objects.is_some_and(|o| o.whole_batch()) {
            (range.len(), 1)
        } else if objects.is_some() {
            (1, 1)
        } else {
            (CHUNK, MIN_CHUNKS_PER_TASK)
        };
        let stress = pts.stress[range.clone()].par_chunks_mut(chunk);
        let dstrain = pts.dstrain[range.clone()].par_chunks(chunk);
        let results: Vec<Result<()>> = if stride == 0 {
            stress
                .zip(dstrain)
                .enumerate()
                .with_min_len(min_chunks)
                .map(|(j, (s, de))| law.update(LawBatch { first: j * chunk, stress: s, dstrain: de, state: &mut [] }))
                .collect()
        } else {
            stress
                .zip(dstrain)
                .zip(m.state.par_chunks_mut(chunk * stride))
                .enumerate()
                .with_min_len(min_chunks)
                .map(|(j, ((s, de), state))| law.update(LawBatch { first: j * chunk, stress: s, dstrain: de, state }))
                .collect()
        };
        if let Some(Err(e)) = results.into_iter().find(|r| r.is_err()) {
            return Err(GraniteError::Other(format!("material \"{}\" ({}): {e}", m.name, law.name())));
        }
        if let Some(objects) = objects {
            objects
                .complete_update(&mut pts.stress[range], &mut m.state)
                .and_then(|copies| copies.into_iter().try_for_each(|(from, to)| objects.copy_object(from, to)))
                .map_err(|e| GraniteError::Other(format!("material \"{}\" ({}): {e}", m.name, law.name())))?;
        }
    }
    Ok(())
}
