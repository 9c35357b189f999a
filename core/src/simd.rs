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
