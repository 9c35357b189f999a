//! Wider instructions for the hot loops, chosen at run time.
//!
//! The DEM kernels are scalar arithmetic on 3-vectors; compiled for AVX2 they need about 14 % fewer
//! instructions (three-operand encoding: no register copies), which is worth 6-8 % of a step. A
//! portable build cannot assume AVX2, so each kernel gets a twin compiled for AVX2
//! ([`wide_kernel!`](crate::wide_kernel)), called when the CPU has it. Only instruction encoding changes:
//! no fused multiply-add is enabled and Rust never reassociates floating point, so results are
//! bitwise the same either way (`GRANITE_NO_AVX2=1` turns the wide path off, to check that).

/// Defines `fn $name($arg: $ty)` that runs `$kernel($arg)` compiled for AVX2 where the CPU has
/// it (and as compiled otherwise). `$kernel` must be `#[inline(always)]`, and so must what it calls
/// in its loops: only code inlined into the AVX2 twin gets the wider instructions (closures are
/// not inlined for certain, so kernels avoid them).
#[macro_export]
macro_rules! wide_kernel {
    ($vis:vis fn $name:ident($arg:ident: $ty:ty) => $kernel:path) => {
        $crate::wide_kernel!($vis fn $name($arg: $ty) -> () => $kernel);
    };
    ($vis:vis fn $name:ident($arg:ident: $ty:ty) -> $ret:ty => $kernel:path) => {
        $vis fn $name($arg: $ty) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                unsafe fn with_avx2($arg: $ty) -> $ret {
                    $kernel($arg)
                }
                if $crate::simd::avx2() {
                    // SAFETY: the CPU supports AVX2, checked at run time by `simd::avx2`.
                    return unsafe { with_avx2($arg) };
                }
            }
            $kernel($arg)
        }
    };
}

/// Defines `fn $name(batch: ContactBatch)` that runs `batch.for_each(&mut $physics)` (a
/// [`ContactPhysics`](crate::ext::contact::ContactPhysics) whose `contact` is `#[inline(always)]`)
/// with an AVX2 twin: the batch loop of a contact law.
#[macro_export]
macro_rules! contact_kernel {
    ($vis:vis fn $name:ident => $physics:expr) => {
        $vis fn $name(batch: $crate::ext::ContactBatch<'_>) {
            #[inline(always)]
            fn each(batch: $crate::ext::ContactBatch<'_>) {
                batch.for_each(&mut $physics)
            }
            $crate::wide_kernel!(fn wide(batch: $crate::ext::ContactBatch<'_>) => each);
            wide(batch)
        }
    };
}

/// Whether the kernels use their AVX2 twins in this process.
pub fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *ON.get_or_init(|| std::env::var_os("GRANITE_NO_AVX2").is_none() && std::is_x86_feature_detected!("avx2"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A 3-vector in the first three of four lanes (the fourth is zero): one 256-bit register in
/// the AVX2 twins, two 128-bit ones otherwise. Each lane does what the scalar code does to its
/// component, in the same order, so results are bitwise the same as component-wise code.
pub type Lanes = [f64; 4];

/// `v` in lanes, the fourth zero.
#[inline(always)]
pub fn widen(v: [f64; 3]) -> Lanes {
    [v[0], v[1], v[2], 0.0]
}

/// The first three lanes.
#[inline(always)]
pub fn narrow(l: Lanes) -> [f64; 3] {
    [l[0], l[1], l[2]]
}

#[inline(always)]
pub fn add4(a: Lanes, b: Lanes) -> Lanes {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]]
}

#[inline(always)]
pub fn sub4(a: Lanes, b: Lanes) -> Lanes {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3]]
}

#[inline(always)]
pub fn mul4(a: Lanes, b: Lanes) -> Lanes {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2], a[3] * b[3]]
}

#[inline(always)]
pub fn scale4(a: Lanes, s: f64) -> Lanes {
    mul4(a, [s; 4])
}

/// The columns of a 3x3 matrix as lanes, for [`mat_vec4`].
pub fn columns(m: &nalgebra::Matrix3<f64>) -> [Lanes; 3] {
    [0, 1, 2].map(|c| [m[(0, c)], m[(1, c)], m[(2, c)], 0.0])
}

/// `m x` from the columns of `m`: each lane sums `m[(r, 0)] x0 + m[(r, 1)] x1 + m[(r, 2)] x2`
/// in that order, as [`crate::math::mat_vec`] does.
#[inline(always)]
pub fn mat_vec4(columns: &[Lanes; 3], x: Lanes) -> Lanes {
    add4(add4(scale4(columns[0], x[0]), scale4(columns[1], x[1])), scale4(columns[2], x[2]))
}

/// `(1 / a, 1 / b)` from one packed division: the divider is the slowest unit the integration
/// uses, and a packed division takes it as long as a scalar one. Each lane is the correctly
/// rounded quotient, as the scalar division gives.
#[inline(always)]
pub fn reciprocals(a: f64, b: f64) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cvtsd_f64, _mm_div_pd, _mm_set1_pd, _mm_set_pd, _mm_unpackhi_pd};
        // SSE2 is part of every x86-64 CPU, so these are always available.
        #[allow(unused_unsafe)]
        unsafe {
            let q = _mm_div_pd(_mm_set1_pd(1.0), _mm_set_pd(b, a));
            (_mm_cvtsd_f64(q), _mm_cvtsd_f64(_mm_unpackhi_pd(q, q)))
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        (1.0 / a, 1.0 / b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_reciprocals_are_the_scalar_ones_bit_for_bit() {
        let values = [2.6e-3, 7.0, 1.0 / 3.0, 1e-300, 5e-324, 1e300, -4.2e-9, 0.0, f64::INFINITY];
        for &a in &values {
            for &b in &values {
                let (ra, rb) = reciprocals(a, b);
                assert_eq!((ra.to_bits(), rb.to_bits()), ((1.0 / a).to_bits(), (1.0 / b).to_bits()), "{a}, {b}");
            }
        }
    }
}
