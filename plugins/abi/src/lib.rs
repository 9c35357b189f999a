//! The C ABI between granite and a native constitutive-law plugin (a `cdylib`).
//!
//! A plugin exports one symbol, `granite_law_table`, returning a pointer to a static
//! [`LawTable`]: plain data and `extern "C"` functions, checked by granite against
//! [`ABI_VERSION`] and the table's size before use. Write the law as a safe Rust type
//! implementing [`NativeLaw`] and let [`export_law!`] generate the table; every exported function
//! catches panics, so a panic becomes an error message, never an unwind across the boundary.
//! granite never unloads a library it has loaded.
//!
//! Conventions are granite's: stresses tension positive, Voigt order xx, yy, zz, xy, yz, xz,
//! strains with engineering shear, stress updated from a strain increment.

use std::ffi::{c_char, c_void};

/// Bumped whenever [`LawTable`] or what it promises changes. 2 added `wave_speed`; 3 ends the
/// lists of parameter and state names with a null pointer, so that granite checks the counts the
/// table declares against the names it holds. granite still loads tables of versions 1
/// ([`LawTableV1`]; its laws report no wave speed) and 2, trusting their counts.
pub const ABI_VERSION: u32 = 3;

/// Where a function writes an error message (UTF-8, truncated to the buffer).
#[repr(C)]
pub struct ErrorBuffer {
    pub text: [u8; 512],
    pub len: usize,
}

impl ErrorBuffer {
    pub fn set(&mut self, message: &str) {
        let n = message.len().min(self.text.len());
        self.text[..n].copy_from_slice(&message.as_bytes()[..n]);
        self.len = n;
    }

    pub fn message(&self) -> String {
        String::from_utf8_lossy(&self.text[..self.len.min(self.text.len())]).into_owned()
    }
}

/// A `*const c_char` that may live in a `static` (plugin strings are static and immutable).
#[repr(transparent)]
#[derive(Clone, Copy)]
pub struct CStrPtr(pub *const c_char);
unsafe impl Sync for CStrPtr {}

/// The table a plugin exports: the fields of version 1 ([`LawTableV1`]) first, then those added
/// since. Strings are NUL-terminated and static.
#[repr(C)]
pub struct LawTable {
    pub head: LawTableV1,
    /// Speed of the fastest (P) wave of the law at a density, m/s, for the time-step limit
    /// (`sim.critical_dt()`); NaN when the law does not know it.
    pub wave_speed: unsafe extern "C" fn(law: *const c_void, density: f64) -> f64,
}

unsafe impl Sync for LawTable {}

/// The table of ABI version 1, and the leading fields of every later one. Strings are
/// NUL-terminated and static.
#[repr(C)]
pub struct LawTableV1 {
    pub abi_version: u32,
    /// The size of the whole table as the plugin saw it (`size_of::<LawTable>()` of its version).
    pub table_size: u32,
    pub name: CStrPtr,
    pub version: CStrPtr,
    pub param_count: usize,
    /// `param_count` names, then (from version 3) a null pointer.
    pub param_names: *const CStrPtr,
    pub state_count: usize,
    /// `state_count` names, then (from version 3) a null pointer.
    pub state_names: *const CStrPtr,
    /// Builds a law from `param_count` values; null with a message on error.
    pub create: unsafe extern "C" fn(params: *const f64, count: usize, err: *mut ErrorBuffer) -> *mut c_void,
    /// Updates `n` points: `stress` and `dstrain` hold 6 values per point, `state` holds
    /// `state_count` per point. Returns 0, or non-zero with a message.
    pub update: unsafe extern "C" fn(
        law: *const c_void,
        n: usize,
        stress: *mut f64,
        dstrain: *const f64,
        state: *mut f64,
        err: *mut ErrorBuffer,
    ) -> i32,
    pub destroy: unsafe extern "C" fn(law: *mut c_void),
}

unsafe impl Sync for LawTableV1 {}

/// A constitutive law written in safe Rust, exported with [`export_law!`].
pub trait NativeLaw: Sized + Send + Sync + 'static {
    /// Builds the law from its parameters, in the order declared to `export_law!`.
    fn new(params: &[f64]) -> Result<Self, String>;
    /// Updates the stress and state of points from their strain increments.
    fn update(&self, stress: &mut [[f64; 6]], dstrain: &[[f64; 6]], state: &mut [f64]) -> Result<(), String>;
    /// Speed of the fastest (P) wave at `density`, m/s: `sqrt((K + 4G/3) / rho)` for isotropic
    /// elasticity. granite's time-step limit (`sim.critical_dt()`) needs it; None leaves the
    /// time step to the user.
    fn wave_speed(&self, density: f64) -> Option<f64> {
        let _ = density;
        None
    }
}

/// Exports a [`NativeLaw`] as `granite_law_table`:
/// `export_law!(MyLaw, name = "my_law", version = "1.0", params = ["young", "poisson"], state = ["eps_p"]);`
#[macro_export]
macro_rules! export_law {
    ($ty:ty, name = $name:expr, version = $version:expr, params = [$($p:expr),* $(,)?], state = [$($s:expr),* $(,)?]) => {
        // Each list ends with a null pointer (ABI version 3): granite counts the names against
        // the declared counts.
        static GRANITE_PARAMS: &[$crate::CStrPtr] = &[$($crate::CStrPtr(concat!($p, "\0").as_ptr() as *const ::std::ffi::c_char),)* $crate::CStrPtr(::std::ptr::null())];
        static GRANITE_STATE: &[$crate::CStrPtr] = &[$($crate::CStrPtr(concat!($s, "\0").as_ptr() as *const ::std::ffi::c_char),)* $crate::CStrPtr(::std::ptr::null())];

        unsafe extern "C" fn granite_create(params: *const f64, count: usize, err: *mut $crate::ErrorBuffer) -> *mut ::std::ffi::c_void {
            let result = ::std::panic::catch_unwind(|| {
                let values = if count == 0 { &[][..] } else { unsafe { ::std::slice::from_raw_parts(params, count) } };
                <$ty as $crate::NativeLaw>::new(values)
            });
            match result {
                Ok(Ok(law)) => Box::into_raw(Box::new(law)) as *mut ::std::ffi::c_void,
                Ok(Err(message)) => {
                    unsafe { (*err).set(&message) };
                    ::std::ptr::null_mut()
                }
                Err(_) => {
                    unsafe { (*err).set("the plugin panicked while creating the law") };
                    ::std::ptr::null_mut()
                }
            }
        }

        unsafe extern "C" fn granite_update(
            law: *const ::std::ffi::c_void,
            n: usize,
            stress: *mut f64,
            dstrain: *const f64,
            state: *mut f64,
            err: *mut $crate::ErrorBuffer,
        ) -> i32 {
            let result = ::std::panic::catch_unwind(::std::panic::AssertUnwindSafe(|| {
                let law = unsafe { &*(law as *const $ty) };
                let stress = unsafe { ::std::slice::from_raw_parts_mut(stress as *mut [f64; 6], n) };
                let dstrain = unsafe { ::std::slice::from_raw_parts(dstrain as *const [f64; 6], n) };
                let per = GRANITE_STATE.len() - 1;
                let state = if per == 0 { &mut [][..] } else { unsafe { ::std::slice::from_raw_parts_mut(state, n * per) } };
                <$ty as $crate::NativeLaw>::update(law, stress, dstrain, state)
            }));
            match result {
                Ok(Ok(())) => 0,
                Ok(Err(message)) => {
                    unsafe { (*err).set(&message) };
                    1
                }
                Err(_) => {
                    unsafe { (*err).set("the plugin panicked while updating") };
                    2
                }
            }
        }

        unsafe extern "C" fn granite_destroy(law: *mut ::std::ffi::c_void) {
            let _ = ::std::panic::catch_unwind(|| unsafe { drop(Box::from_raw(law as *mut $ty)) });
        }

        unsafe extern "C" fn granite_wave_speed(law: *const ::std::ffi::c_void, density: f64) -> f64 {
            ::std::panic::catch_unwind(|| {
                let law = unsafe { &*(law as *const $ty) };
                <$ty as $crate::NativeLaw>::wave_speed(law, density).unwrap_or(f64::NAN)
            })
            .unwrap_or(f64::NAN)
        }

        static GRANITE_TABLE: $crate::LawTable = $crate::LawTable {
            head: $crate::LawTableV1 {
                abi_version: $crate::ABI_VERSION,
                table_size: ::std::mem::size_of::<$crate::LawTable>() as u32,
                name: $crate::CStrPtr(concat!($name, "\0").as_ptr() as *const ::std::ffi::c_char),
                version: $crate::CStrPtr(concat!($version, "\0").as_ptr() as *const ::std::ffi::c_char),
                param_count: [$($p),*].len(),
                param_names: GRANITE_PARAMS.as_ptr(),
                state_count: [$($s),*].len(),
                state_names: GRANITE_STATE.as_ptr(),
                create: granite_create,
                update: granite_update,
                destroy: granite_destroy,
            },
            wave_speed: granite_wave_speed,
        };

        /// The entry point granite looks for.
        #[no_mangle]
        pub extern "C" fn granite_law_table() -> *const $crate::LawTable {
            &GRANITE_TABLE
        }
    };
}
