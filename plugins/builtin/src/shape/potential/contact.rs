//! Contact detection between two potential particles (Boon, Houlsby & Utili 2013).
//!
//! The contact point is the point nearest to both particles in the sense of their potentials:
//! `x* = argmin max(f_A(x), f_B(x))`. Both potentials are convex, so this is a convex problem
//! (Boon et al. write it as a second-order cone program); the particles overlap when its value is
//! negative (a point lies inside both). It is solved here by Newton's method on its optimality
//! conditions, `lambda grad f_A + (1 - lambda) grad f_B = 0` and `f_A = f_B` (both potentials are
//! piecewise quadratic, so Newton ends in a few steps once the active planes settle), from the
//! previous step's solution when there is one.
//!
//! **Stopping criterion.** For any `x` and `lambda` in `[0, 1]`, with `L = lambda f_A + (1 - lambda)
//! f_B`, weak duality gives `min_y L(y) <= min max(f_A, f_B) <= max(f_A(x), f_B(x))`, and `L` is
//! strongly convex with modulus `mu >= 2 (lambda k_A / R_A^2 + (1 - lambda) k_B / R_B^2)` (the
//! shadow spheres' terms), so `min_y L(y) >= L(x) - |grad L(x)|^2 / (2 mu)`. The distance from the
//! optimal value is therefore at most `|f_A(x) - f_B(x)| + |grad L(x)|^2 / (2 mu)`: the solve stops
//! when that bound is below [`VALUE_TOLERANCE`], so whether the particles touch is decided to
//! that tolerance, proven, not assumed.
//!
//! The normal is `grad f_A` at the contact point (from A towards B); the overlap is the length
//! along it between the two surfaces through the contact point, found by a bracketed Newton
//! search on each particle (thesis 2.2.3).

use super::shape::{potential, PotentialShape};
/// The geometry of two touching bodies: unit normal from A towards B, the length along it
/// between the two surfaces through the contact point, and the middle of that overlap (where
/// the force acts).
pub use granite_core::ext::body::Touch;
use granite_core::math::{dot3, Vec3};
use nalgebra::{Matrix3, Vector3};

/// How far from the optimal value of `max(f_A, f_B)` a solution may be. Potentials are
/// dimensionless, about `2 delta / r` at a depth `delta` below the surface: for the thesis's
/// tetrahedron (r = 3.1 mm) whether two particles touch is then decided to 2e-11 m, and the
/// contact point, whose distance from the optimum is at most `|grad L| / mu`, is within 5e-7 m, so
/// the normal within 2e-4 rad. Tighter stops cost a Newton step a contact: at 1e-10 the heap of
/// `granite bench potential` stepped 20 % slower.
pub const VALUE_TOLERANCE: f64 = 1e-8;
/// Most Newton steps of one solve before it turns to the dual's bisection (a contact met before
/// takes one or two; a first meeting up to about ten).
const MAX_STEPS: usize = 25;

/// Where a particle is: its centre of mass and the rotation from its body frame to the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub position: Vec3,
    pub rotation: Matrix3<f64>,
}

impl Pose {
    pub fn at(position: Vec3) -> Pose {
        Pose { position, rotation: Matrix3::identity() }
    }
}

/// A particle's potential where it is: its shape's planes and shadow sphere moved into world
/// coordinates once, so that each evaluation costs what the shape's own does.
#[derive(Debug, Clone, Default)]
pub struct Placed {
    planes: Vec<(Vec3, f64)>,
    sphere_centre: Vec3,
    pub position: Vec3,
    weights: [f64; 2],
    /// Strong-convexity modulus of the potential: that of its shadow sphere term, `2 k / R^2`.
    modulus: f64,
    pub bounding_radius: f64,
    /// How far the surface may stand off a plane: `r / sqrt(1 - k)` (infinite at k = 1).
    standoff: f64,
}

impl Placed {
    pub fn new(shape: &PotentialShape, pose: &Pose) -> Placed {
        let mut placed = Placed::default();
        placed.place(shape, pose);
        placed
    }

    /// Moves `shape` to `pose`, keeping this value's storage.
    pub fn place(&mut self, shape: &PotentialShape, pose: &Pose) {
        let rot = &pose.rotation;
        let to_world = |v: Vec3| {
            let w = rot * Vector3::new(v[0], v[1], v[2]);
            [w[0], w[1], w[2]]
        };
        let x = pose.position;
        self.planes.clear();
        self.planes.extend(shape.planes.iter().map(|&(n, d)| {
            let n = to_world(n);
            (n, d + dot3(n, x))
        }));
        let s = to_world(shape.sphere_centre);
        self.sphere_centre = [s[0] + x[0], s[1] + x[1], s[2] + x[2]];
        self.position = x;
        self.weights = shape.weights();
        self.modulus = 2.0 * self.weights[1];
        self.bounding_radius = shape.bounding_radius;
        self.standoff = if shape.k < 1.0 { shape.r / (1.0 - shape.k).sqrt() } else { f64::INFINITY };
    }

    /// A sphere of `radius` about `centre` as a potential (`k = 1`, no planes): what a particle
    /// meets a sphere of the scene as.
    pub fn sphere(centre: Vec3, radius: f64) -> Placed {
        let weights = [0.0, 1.0 / (radius * radius)];
        Placed {
            planes: Vec::new(),
            sphere_centre: centre,
            position: centre,
            weights,
            modulus: 2.0 * weights[1],
            bounding_radius: radius,
            standoff: f64::INFINITY,
        }
    }

    pub fn value(&self, x: Vec3) -> f64 {
        potential::<false, false>(&self.planes, self.sphere_centre, self.weights, x).0
    }

    /// Whether a ball of `radius` about `centre` lies wholly outside the particle: beyond one of
    /// its planes grown by `r / sqrt(1 - k)`, the most the surface stands off a plane (inside,
    /// `(1 - k)(<n . x - d>^2 / r^2 - 1) <= k`). A cheap proof of separation for long or flat
    /// particles, whose bounding spheres reach far.
    pub fn clear_of(&self, centre: Vec3, radius: f64) -> bool {
        // At k = 1 the stand-off is infinite: the planes prove nothing.
        self.planes.iter().any(|&(n, d)| dot3(n, centre) - d > self.standoff + radius)
    }

    pub(crate) fn value_gradient(&self, x: Vec3) -> (f64, Vector3<f64>) {
        let (f, g, _) = potential::<true, false>(&self.planes, self.sphere_centre, self.weights, x);
        (f, Vector3::new(g[0], g[1], g[2]))
    }

    /// Value, gradient and Hessian at world point `x`.
    pub fn value_gradient_hessian(&self, x: Vec3) -> (f64, Vector3<f64>, Matrix3<f64>) {
        let (f, g, h) = potential::<true, true>(&self.planes, self.sphere_centre, self.weights, x);
        (f, Vector3::new(g[0], g[1], g[2]), h)
    }
}

/// The solution of the contact problem, kept by a pair to start the next step's solve from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Solution {
    pub point: Vec3,
    pub lambda: f64,
    /// The distances from the point to B's and to A's surface along the normal (the overlap's two
    /// parts): where the next step's searches along the normal start.
    pub depths: [f64; 2],
}

/// What a solve found: the solution (to start from next time), the optimal value bracket's upper
/// end `max(f_A, f_B)`, the Newton steps it took, and the geometry when the particles touch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub solution: Solution,
    pub value: f64,
    pub steps: usize,
    pub touch: Option<Touch>,
}

/// The contact problem could not be solved to the tolerance (a diagnostic names the pair).
#[derive(Debug, Clone, PartialEq)]
pub struct NoConvergence {
    pub steps: usize,
    pub gap_bound: f64,
}

impl std::fmt::Display for NoConvergence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "after {} steps its solution was still up to {:.3e} from the optimum (tolerance {VALUE_TOLERANCE:e})",
            self.steps, self.gap_bound
        )
    }
}

/// The contact between `a` and `b`, from `start` (the previous solution) or, without one, from a
/// guess on the line between their centres. A pair proven apart is left there, its solution short
/// of the optimum.
pub fn detect(a: &Placed, b: &Placed, start: Option<Solution>) -> Result<Detection, NoConvergence> {
    solve::<false>(a, b, start)
}

/// [`detect`] solved to the optimum also for a pair apart: what a search over the problem's value
/// or its solution reads (a capsule's sphere sliding along its axis, `capsule_potential`).
pub fn detect_settled(a: &Placed, b: &Placed, start: Option<Solution>) -> Result<Detection, NoConvergence> {
    solve::<true>(a, b, start)
}

fn solve<const SETTLED: bool>(a: &Placed, b: &Placed, start: Option<Solution>) -> Result<Detection, NoConvergence> {
    let Solution { point, lambda, depths } = start.unwrap_or_else(|| first_guess(a, b));
    let mut x = Vector3::new(point[0], point[1], point[2]);
    let mut lambda = lambda.clamp(0.0, 1.0);
    let mut state = Kkt::at(a, b, x);
    let mut steps = 0;
    loop {
        let bound = state.gap_bound(a, b, lambda);
        if bound <= VALUE_TOLERANCE || (!SETTLED && state.apart(a, b, lambda)) {
            break;
        }
        if steps == MAX_STEPS {
            // Newton on the optimality conditions did not settle (a far start against a flat,
            // nearly uncurved face): the dual's bisection, slower but sure.
            (x, lambda, state) = by_bisection(a, b, x)?;
            break;
        }
        steps += 1;
        let (dx, dl) = state.newton_step(lambda);
        // Backtracking on the residual of the optimality conditions (full steps near the
        // solution; a halving keeps a far start from jumping across the particles).
        let residual = state.residual(lambda);
        let mut t = 1.0;
        loop {
            let (x_try, l_try) = (x + dx * t, (lambda + dl * t).clamp(0.0, 1.0));
            let trial = Kkt::at(a, b, x_try);
            if trial.residual(l_try) < residual || t < 1e-6 {
                (x, lambda, state) = (x_try, l_try, trial);
                break;
            }
            t *= 0.5;
        }
    }
    let mut solution = Solution { point: [x[0], x[1], x[2]], lambda, depths };
    let value = state.fa.max(state.fb);
    let touch = (value < 0.0 && !state.apart(a, b, lambda)).then(|| {
        let (touch, depths) = overlap_along_normal(a, b, solution.point, state.ga, depths);
        solution.depths = depths;
        touch
    });
    Ok(Detection { solution, value, steps, touch })
}

/// The optimality conditions' terms at `(x, lambda)`.
struct Kkt {
    x: Vector3<f64>,
    fa: f64,
    fb: f64,
    ga: Vector3<f64>,
    gb: Vector3<f64>,
    ha: Matrix3<f64>,
    hb: Matrix3<f64>,
}

impl Kkt {
    fn at(a: &Placed, b: &Placed, x: Vector3<f64>) -> Kkt {
        let point = [x[0], x[1], x[2]];
        let (fa, ga, ha) = a.value_gradient_hessian(point);
        let (fb, gb, hb) = b.value_gradient_hessian(point);
        Kkt { x, fa, fb, ga, gb, ha, hb }
    }

    fn lagrangian_gradient(&self, lambda: f64) -> Vector3<f64> {
        self.ga * lambda + self.gb * (1.0 - lambda)
    }

    fn residual(&self, lambda: f64) -> f64 {
        self.lagrangian_gradient(lambda).norm_squared() + (self.fa - self.fb).powi(2)
    }

    /// Whether the particles are proven apart: the dual's lower bound on the optimal value,
    /// `L(x) - |grad L|^2 / (2 mu)`, is positive (no point lies inside both). Apart pairs need
    /// no more precision than that.
    fn apart(&self, a: &Placed, b: &Placed, lambda: f64) -> bool {
        let mu = lambda * a.modulus + (1.0 - lambda) * b.modulus;
        let lagrangian = lambda * self.fa + (1.0 - lambda) * self.fb;
        lagrangian - self.lagrangian_gradient(lambda).norm_squared() / (2.0 * mu) > 0.0
    }

    /// The proven distance from the optimal value (see the module's text).
    fn gap_bound(&self, a: &Placed, b: &Placed, lambda: f64) -> f64 {
        let mu = lambda * a.modulus + (1.0 - lambda) * b.modulus;
        (self.fa - self.fb).abs() + self.lagrangian_gradient(lambda).norm_squared() / (2.0 * mu)
    }

    /// Newton's step on `grad L = 0, f_A - f_B = 0`.
    fn newton_step(&self, lambda: f64) -> (Vector3<f64>, f64) {
        let h = self.ha * lambda + self.hb * (1.0 - lambda);
        let c = self.ga - self.gb;
        let g = self.lagrangian_gradient(lambda);
        match saddle_solve(&h, &c, &g, self.fa - self.fb) {
            Some(step) => step,
            // Equal gradients (never at a solution): a gradient step on L instead.
            None => (-g * 0.5 / h.norm().max(f64::MIN_POSITIVE), 0.0),
        }
    }
}

/// The solution of `[[H, c], [c^T, 0]] (dx, dl) = -(g, r)` with `H` symmetric positive definite
/// (3 x 3): by the Schur complement, `dl = (r - c^T H^-1 g) / (c^T H^-1 c)`, `dx = -H^-1 (g + c dl)`
/// (a Cholesky factor of `H` serves both solves). None when `H` is not positive definite or
/// `c` vanishes.
#[inline]
fn saddle_solve(h: &Matrix3<f64>, c: &Vector3<f64>, g: &Vector3<f64>, r: f64) -> Option<(Vector3<f64>, f64)> {
    let chol = h.cholesky()?;
    let (hc, hg) = (chol.solve(c), chol.solve(g));
    let schur = c.dot(&hc);
    if !(schur > 0.0) {
        return None;
    }
    let dl = (r - c.dot(&hg)) / schur;
    Some((-(hg + hc * dl), dl))
}

/// The contact problem through its dual, `max over lambda in [0, 1] of min_x L(x, lambda)`: the
/// dual is concave, its slope at `lambda` is `f_A - f_B` at that `lambda`'s minimiser, which falls
/// as `lambda` grows, so bisection on its sign finds the optimum; each `min_x L` is a strictly
/// convex problem, solved by Newton's method with backtracking on `L` (globally convergent). Ends
/// with the same proven bound as [`detect`].
fn by_bisection(a: &Placed, b: &Placed, from: Vector3<f64>) -> Result<(Vector3<f64>, f64, Kkt), NoConvergence> {
    let minimise = |lambda: f64, x: Vector3<f64>| -> Kkt {
        let mut state = Kkt::at(a, b, x);
        for _ in 0..200 {
            let mu = lambda * a.modulus + (1.0 - lambda) * b.modulus;
            let g = state.lagrangian_gradient(lambda);
            if g.norm_squared() / (2.0 * mu) <= 0.1 * VALUE_TOLERANCE {
                break;
            }
            let h = state.ha * lambda + state.hb * (1.0 - lambda);
            let Some(chol) = h.cholesky() else { break };
            let dx = -chol.solve(&g);
            let value = |k: &Kkt| lambda * k.fa + (1.0 - lambda) * k.fb;
            let now = value(&state);
            let mut t = 1.0;
            loop {
                let trial = Kkt::at(a, b, state.x + dx * t);
                // Armijo: enough decrease of L along the Newton direction.
                if value(&trial) <= now + 1e-4 * t * g.dot(&dx) || t < 1e-12 {
                    state = trial;
                    break;
                }
                t *= 0.5;
            }
        }
        state
    };
    let (mut lo, mut hi) = (0.0, 1.0);
    let mut lambda = 0.5;
    let mut state = minimise(lambda, from);
    for _ in 0..80 {
        if state.gap_bound(a, b, lambda) <= VALUE_TOLERANCE || state.apart(a, b, lambda) {
            return Ok((state.x, lambda, state));
        }
        if state.fa > state.fb {
            lo = lambda;
        } else {
            hi = lambda;
        }
        lambda = 0.5 * (lo + hi);
        state = minimise(lambda, state.x);
    }
    let bound = state.gap_bound(a, b, lambda);
    if bound <= VALUE_TOLERANCE || state.apart(a, b, lambda) {
        Ok((state.x, lambda, state))
    } else {
        Err(NoConvergence { steps: MAX_STEPS + 80, gap_bound: bound })
    }
}

/// A start for a pair seen for the first time: on the line between the centres, where each
/// particle's surface leaves off, halfway between the two (exact for two spheres), with the
/// weight that balances the two gradients there.
fn first_guess(a: &Placed, b: &Placed) -> Solution {
    let (ca, cb) = (a.position, b.position);
    let d = [cb[0] - ca[0], cb[1] - ca[1], cb[2] - ca[2]];
    let length = dot3(d, d).sqrt();
    if !(length > 0.0) {
        return Solution { point: ca, lambda: 0.5, depths: [0.0; 2] };
    }
    let u = d.map(|c| c / length);
    let reach_a = along_ray(a, ca, u, a.bounding_radius, 0.0);
    let reach_b = along_ray(b, cb, u.map(|c| -c), b.bounding_radius, 0.0);
    // The surface points of A towards B and of B towards A, and their middle.
    let s = 0.5 * (reach_a + length - reach_b);
    let point = [ca[0] + s * u[0], ca[1] + s * u[1], ca[2] + s * u[2]];
    let (ga, gb) = (a.value_gradient(point).1.norm(), b.value_gradient(point).1.norm());
    let lambda = if ga + gb > 0.0 { gb / (ga + gb) } else { 0.5 };
    Solution { point, lambda, depths: [0.0; 2] }
}

/// The distance from `from` (inside the particle) along unit `u` to its surface, within `reach`:
/// the root of `f` along the ray, by Newton's method kept inside a bracket, from `guess` (the
/// last step's distance, or 0). Along a ray `f` is a convex piecewise quadratic, negative at the
/// start: Newton from a point where `f` increases lands beyond the root, then comes back to it
/// from above, each step inside the bracket.
pub(crate) fn along_ray(p: &Placed, from: Vec3, u: Vec3, reach: f64, guess: f64) -> f64 {
    let at = |t: f64| [from[0] + t * u[0], from[1] + t * u[1], from[2] + t * u[2]];
    let (mut lo, mut hi) = (0.0, reach.max(f64::MIN_POSITIVE));
    let mut t = if guess > 0.0 && guess < hi { guess } else { 0.0 };
    for _ in 0..100 {
        let (f, g) = p.value_gradient(at(t));
        if f > 0.0 {
            hi = t;
        } else {
            lo = t;
        }
        let slope = g[0] * u[0] + g[1] * u[1] + g[2] * u[2];
        let newton = if slope > 0.0 { t - f / slope } else { f64::NAN };
        let next = if newton > lo && newton < hi { newton } else { 0.5 * (lo + hi) };
        if (next - t).abs() <= 1e-13 * reach {
            return next;
        }
        t = next;
    }
    t
}

/// The overlap along the normal `grad f_A` at the contact point `x` (inside both particles), and
/// its two parts (to B's surface, to A's), searched for from `guess`.
fn overlap_along_normal(a: &Placed, b: &Placed, x: Vec3, ga: Vector3<f64>, guess: [f64; 2]) -> (Touch, [f64; 2]) {
    let norm = ga.norm();
    let normal = [ga[0] / norm, ga[1] / norm, ga[2] / norm];
    let back = normal.map(|c| -c);
    // A's surface lies ahead along the normal, B's behind; neither beyond the other's size.
    let (into_b, into_a) = (
        along_ray(a, x, normal, 2.0 * a.bounding_radius, guess[0]),
        along_ray(b, x, back, 2.0 * b.bounding_radius, guess[1]),
    );
    let middle = 0.5 * (into_b - into_a);
    let touch = Touch { normal, overlap: into_b + into_a, point: [0, 1, 2].map(|i| x[i] + middle * normal[i]) };
    (touch, [into_b, into_a])
}

/// The contact of a particle with a plane through `point` whose unit `normal` points to the
/// particles' side: the particle's deepest point below the plane, `argmin normal . x` over
/// `f <= 0`, from Newton's method on `normal + mu grad f = 0, f = 0` (started from `start`, the
/// previous deepest point, or from the centre's ray against the normal). It stops when the
/// point is on the surface and the stationarity residual, over the shadow sphere's modulus, is
/// below `LENGTH_TOLERANCE` of the particle's size. The normal of the touch points from the
/// particle into the wall (`-normal`).
pub fn detect_plane(
    p: &Placed,
    point: Vec3,
    normal: Vec3,
    start: Option<Vec3>,
) -> Result<(Vec3, Option<Touch>), NoConvergence> {
    let size = p.bounding_radius;
    let n = Vector3::new(normal[0], normal[1], normal[2]);
    let mut x = match start {
        Some(s) => Vector3::new(s[0], s[1], s[2]),
        None => {
            let c = p.position;
            let t = along_ray(p, c, normal.map(|v| -v), size, 0.0);
            Vector3::new(c[0] - t * normal[0], c[1] - t * normal[1], c[2] - t * normal[2])
        }
    };
    let (_, g) = p.value_gradient([x[0], x[1], x[2]]);
    let mut mu = 1.0 / g.norm().max(f64::MIN_POSITIVE);
    let modulus = p.modulus;
    let mut steps = 0;
    loop {
        let (f, g, h) = p.value_gradient_hessian([x[0], x[1], x[2]]);
        let stationarity = n + g * mu;
        // Distance along the normal still in doubt: the surface residual through the gradient,
        // and the stationarity residual through the strong convexity (as in `detect`).
        let doubt = f.abs() / g.norm().max(f64::MIN_POSITIVE) + stationarity.norm_squared() / (2.0 * mu * modulus);
        if doubt <= LENGTH_TOLERANCE * size {
            break;
        }
        if steps == MAX_STEPS {
            return Err(NoConvergence { steps, gap_bound: doubt / size });
        }
        steps += 1;
        let Some((dx, dmu)) = saddle_solve(&(h * mu), &g, &stationarity, f) else {
            return Err(NoConvergence { steps, gap_bound: doubt / size });
        };
        let step = [dx[0], dx[1], dx[2], dmu];
        // The multiplier stays positive, and a step is halved until it lowers the residual of the
        // optimality conditions: on a flat face the tangential curvature is the shadow sphere's
        // alone, and a full step from off the deepest point can jump far across the surface.
        let residual = |x: Vector3<f64>, mu: f64| {
            let (f, g) = p.value_gradient([x[0], x[1], x[2]]);
            (n + g * mu).norm_squared() + (f / g.norm().max(f64::MIN_POSITIVE) / size).powi(2)
        };
        let now = residual(x, mu);
        let mut t = 1.0;
        while mu + t * step[3] <= 0.0 && t > 1e-6 {
            t *= 0.5;
        }
        while t > 1e-6 && residual(x + Vector3::new(step[0], step[1], step[2]) * t, mu + t * step[3]) >= now {
            t *= 0.5;
        }
        x += Vector3::new(step[0], step[1], step[2]) * t;
        mu += t * step[3];
    }
    let deepest = [x[0], x[1], x[2]];
    let depth = -(0..3).map(|i| normal[i] * (deepest[i] - point[i])).sum::<f64>();
    let touch = (depth > 0.0).then(|| Touch {
        normal: normal.map(|v| -v),
        overlap: depth,
        point: [0, 1, 2].map(|i| deepest[i] + 0.5 * depth * normal[i]),
    });
    Ok((deepest, touch))
}

/// How far from the exact deepest point a plane contact's solve may stop, relative to the
/// particle's bounding radius.
pub const LENGTH_TOLERANCE: f64 = 1e-11;

#[cfg(test)]
mod tests {
    use super::super::shape::{box_planes, PotentialShape};
    use super::*;
    use nalgebra::{Rotation3, Unit};

    fn sphere(radius: f64) -> PotentialShape {
        PotentialShape::new(&box_planes([0.5 * radius; 3]), 0.3 * radius, radius, 1.0, 40).unwrap()
    }

    /// k = 1 particles are spheres of radius R: they touch when their centres are closer than the
    /// sum of the radii, with the overlap and the normal of two spheres.
    #[test]
    fn spheres_overlap_as_spheres_do() {
        let (ra, rb) = (2e-3, 3e-3);
        let (a, b) = (sphere(ra), sphere(rb));
        let centre_a = a.sphere_centre.map(|c| -c);
        let pa = Pose::at(centre_a);
        for (distance, direction) in [(4.9e-3, [1.0, 0.0, 0.0]), (4.5e-3, [0.6, 0.0, 0.8]), (5.1e-3, [0.0, 1.0, 0.0])] {
            let offset = b.sphere_centre;
            let pb = Pose::at([0, 1, 2].map(|i| direction[i] * distance - offset[i]));
            let found = detect(&Placed::new(&a, &pa), &Placed::new(&b, &pb), None).unwrap();
            let expected = ra + rb - distance;
            match found.touch {
                None => assert!(expected < 0.0, "{distance}: no contact found"),
                Some(t) => {
                    assert!(
                        (t.overlap - expected).abs() < 1e-12 * ra,
                        "{distance}: overlap {} against {expected}",
                        t.overlap
                    );
                    for i in 0..3 {
                        assert!((t.normal[i] - direction[i]).abs() < 1e-9, "normal {:?}", t.normal);
                    }
                    // The force acts in the middle of the overlap: ra - overlap / 2 from A's centre.
                    let along = dot3(t.point, direction);
                    assert!((along - (ra - 0.5 * expected)).abs() < 1e-12 * ra);
                }
            }
        }
    }

    /// Two cubes (k small) pressed face to face by a depth `delta`: the overlap is `delta` and the
    /// normal the faces' normal, whichever way they are turned about it.
    #[test]
    fn cubes_face_to_face_overlap_by_the_depth_pressed() {
        let (half, r) = (2e-3, 2e-4);
        let cube = PotentialShape::new(&box_planes([half; 3]), r, 20.0 * half, 1e-4, 60).unwrap();
        // Centres on x, 2 (half + r) - delta apart; B turned about x by 30 degrees.
        let delta = 5e-5;
        let turn = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::x()), 0.5).into_inner();
        let c = cube.sphere_centre;
        let pa = Pose { position: c.map(|v| -v), rotation: Matrix3::identity() };
        let pb = Pose { position: [2.0 * (half + r) - delta, 0.0, 0.0], rotation: turn };
        let found = detect(&Placed::new(&cube, &pa), &Placed::new(&cube, &pb), None).unwrap();
        let t = found.touch.expect("pressed cubes touch");
        // The faces are flat where k = 0; the shadow sphere's small share (k = 1e-4, R = 20 half)
        // moves them by a fraction of order k of r, well within 1e-3 of the depth.
        assert!((t.overlap / delta - 1.0).abs() < 1e-3, "overlap {} against {delta}", t.overlap);
        assert!((t.normal[0] - 1.0).abs() < 1e-6, "normal {:?}", t.normal);
    }

    /// From the previous step's solution, a slightly moved pair is solved in a step or two.
    #[test]
    fn a_warm_start_takes_few_steps() {
        let (r_s, r_clump) = (0.3101e-2, 0.5e-2);
        let tetra = PotentialShape::rounded_tetrahedron(r_s, r_clump, 2f64.sqrt() * r_s, 0.65).unwrap();
        let turn = |angle: f64| {
            Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)), angle).into_inner()
        };
        let pa = Pose { position: [0.0; 3], rotation: turn(0.3) };
        let mut previous = None;
        let mut cold_steps = 0;
        for step in 0..20 {
            let pb =
                Pose { position: [8.5e-3 - 1e-5 * step as f64, 1e-3, 0.0], rotation: turn(1.0 + 1e-3 * step as f64) };
            let found = detect(&Placed::new(&tetra, &pa), &Placed::new(&tetra, &pb), previous).unwrap();
            if step == 0 {
                cold_steps = found.steps;
            } else {
                assert!(found.steps <= 3, "step {step}: {} Newton steps from the previous solution", found.steps);
                let cold = detect(&Placed::new(&tetra, &pa), &Placed::new(&tetra, &pb), None).unwrap();
                assert!((cold.value - found.value).abs() <= 2.0 * VALUE_TOLERANCE);
            }
            previous = Some(found.solution);
        }
        assert!(cold_steps > 0);
    }

    /// A particle pressed into a plane by `delta`: k = 1 (a sphere) and a cube turned about the
    /// plane's normal give the depth, the normal and the force point of a flat contact.
    #[test]
    fn a_plane_is_touched_at_the_deepest_point() {
        let r_big = 2e-3;
        let ball = sphere(r_big);
        let c = ball.sphere_centre;
        let delta = 1e-4;
        let pose = Pose::at([1.0 - c[0], 2.0 - c[1], r_big - delta - c[2]]);
        let (deepest, touch) = detect_plane(&Placed::new(&ball, &pose), [0.0; 3], [0.0, 0.0, 1.0], None).unwrap();
        let t = touch.expect("a sphere below the plane's level touches it");
        assert!((t.overlap - delta).abs() < 1e-12 * r_big, "overlap {}", t.overlap);
        assert!((deepest[0] - 1.0).abs() < 1e-9 && (deepest[1] - 2.0).abs() < 1e-9);
        assert_eq!(t.normal, [0.0, 0.0, -1.0]);
        let (half, r) = (2e-3, 2e-4);
        let cube = PotentialShape::new(&box_planes([half; 3]), r, 20.0 * half, 1e-4, 60).unwrap();
        let turn = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::z()), 0.7).into_inner();
        let pose = Pose { position: [0.0, 0.0, half + r - delta], rotation: turn };
        let (_, touch) = detect_plane(&Placed::new(&cube, &pose), [0.0; 3], [0.0, 0.0, 1.0], None).unwrap();
        let t = touch.expect("pressed cube touches");
        assert!((t.overlap / delta - 1.0).abs() < 1e-3, "overlap {}", t.overlap);
        // Lifted clear of the plane: no touch.
        let pose = Pose::at([0.0, 0.0, r_big + delta]);
        assert!(detect_plane(&Placed::new(&ball, &pose), [0.0; 3], [0.0, 0.0, 1.0], None).unwrap().1.is_none());
    }
}
