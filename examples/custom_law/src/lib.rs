//! A Drucker-Prager law as a granite plugin (copy this crate to write your own law).
//!
//! Yield function `f = sqrt(J2) + alpha I1 - k` (tension positive: compression raises the
//! strength), isotropic elasticity, non-associated flow without dilatancy: a plastic trial keeps
//! its mean stress and its deviator is scaled back onto the surface (radial return); a trial in
//! more tension than the cone's apex `I1 = k / alpha` returns to the apex. State variable: the
//! accumulated plastic shear `gamma_p`.
//!
//! Build: `cargo build --release -p custom_law`; load: `load_plugin("target/release/libcustom_law.so")`
//! in a script or `granite run --plugin ...`; use: `sim.material("drucker_prager", #{ density: ...,
//! young: ..., poisson: ..., alpha: ..., k: ... })`.

use granite_plugin_abi::NativeLaw;

pub struct DruckerPrager {
    lambda: f64,
    shear: f64,
    alpha: f64,
    k: f64,
}

impl NativeLaw for DruckerPrager {
    fn new(p: &[f64]) -> Result<Self, String> {
        let (young, poisson, alpha, k) = (p[0], p[1], p[2], p[3]);
        if young.is_nan() || young <= 0.0 {
            return Err(format!("young = {young}: must be > 0"));
        }
        if !(poisson > -1.0 && poisson < 0.5) {
            return Err(format!("poisson = {poisson}: must be in (-1, 0.5)"));
        }
        if !(alpha >= 0.0 && k >= 0.0) {
            return Err(format!("alpha = {alpha}, k = {k}: must be >= 0"));
        }
        let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
        Ok(DruckerPrager { lambda, shear: young / (2.0 * (1.0 + poisson)), alpha, k })
    }

    /// P-wave speed of the elastic part, sqrt((lambda + 2G) / rho): granite's time-step limit.
    fn wave_speed(&self, density: f64) -> Option<f64> {
        Some(((self.lambda + 2.0 * self.shear) / density).sqrt())
    }

    fn update(&self, stress: &mut [[f64; 6]], dstrain: &[[f64; 6]], state: &mut [f64]) -> Result<(), String> {
        for ((s, de), gp) in stress.iter_mut().zip(dstrain).zip(state.iter_mut()) {
            let tr = de[0] + de[1] + de[2];
            for a in 0..3 {
                s[a] += self.lambda * tr + 2.0 * self.shear * de[a];
                s[a + 3] += self.shear * de[a + 3];
            }
            let i1 = s[0] + s[1] + s[2];
            let p = i1 / 3.0;
            let dev = [s[0] - p, s[1] - p, s[2] - p];
            let j2 =
                0.5 * (dev[0] * dev[0] + dev[1] * dev[1] + dev[2] * dev[2]) + s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
            let tau = j2.sqrt();
            if self.alpha > 0.0 && i1 > self.k / self.alpha {
                // More tension than the cone's apex holds (p > k / 3 alpha): back to the apex, an
                // isotropic stress; a cohesionless soil (k = 0) carries no tension at all.
                let apex = self.k / (3.0 * self.alpha);
                *s = [apex, apex, apex, 0.0, 0.0, 0.0];
                *gp += tau / self.shear;
                continue;
            }
            let limit = self.k - self.alpha * i1;
            if tau > limit {
                let scale = if tau > 0.0 { limit / tau } else { 0.0 };
                for a in 0..3 {
                    s[a] = p + dev[a] * scale;
                    s[a + 3] *= scale;
                }
                *gp += (tau - limit) / self.shear;
            }
        }
        Ok(())
    }
}

#[cfg(not(any(feature = "wrong_abi", feature = "abi_v1")))]
granite_plugin_abi::export_law!(
    DruckerPrager,
    name = "drucker_prager",
    version = "0.1.0",
    params = ["young", "poisson", "alpha", "k"],
    state = ["gamma_p"]
);

/// A table claiming another ABI version, for granite's rejection test.
#[cfg(feature = "wrong_abi")]
mod wrong {
    use granite_plugin_abi::{CStrPtr, ErrorBuffer, LawTable, LawTableV1};
    use std::ffi::c_void;
    unsafe extern "C" fn create(_: *const f64, _: usize, _: *mut ErrorBuffer) -> *mut c_void {
        std::ptr::null_mut()
    }
    unsafe extern "C" fn update(
        _: *const c_void,
        _: usize,
        _: *mut f64,
        _: *const f64,
        _: *mut f64,
        _: *mut ErrorBuffer,
    ) -> i32 {
        1
    }
    unsafe extern "C" fn destroy(_: *mut c_void) {}
    unsafe extern "C" fn wave_speed(_: *const c_void, _: f64) -> f64 {
        f64::NAN
    }
    static TABLE: LawTable = LawTable {
        head: LawTableV1 {
            abi_version: granite_plugin_abi::ABI_VERSION + 100,
            table_size: std::mem::size_of::<LawTable>() as u32,
            name: CStrPtr(c"drucker_prager".as_ptr()),
            version: CStrPtr(c"0.0.0".as_ptr()),
            param_count: 0,
            param_names: std::ptr::null(),
            state_count: 0,
            state_names: std::ptr::null(),
            create,
            update,
            destroy,
        },
        wave_speed,
    };
    #[no_mangle]
    pub extern "C" fn granite_law_table() -> *const LawTable {
        &TABLE
    }
}

/// The same law through a table of ABI version 1 (before `wave_speed`), for granite's test of
/// its loading path for older plugins.
#[cfg(feature = "abi_v1")]
mod version_1 {
    use super::DruckerPrager;
    use granite_plugin_abi::{CStrPtr, ErrorBuffer, LawTableV1, NativeLaw};
    use std::ffi::c_void;
    unsafe extern "C" fn create(p: *const f64, n: usize, err: *mut ErrorBuffer) -> *mut c_void {
        match DruckerPrager::new(unsafe { std::slice::from_raw_parts(p, n) }) {
            Ok(law) => Box::into_raw(Box::new(law)) as *mut c_void,
            Err(e) => {
                unsafe { (*err).set(&e) };
                std::ptr::null_mut()
            }
        }
    }
    unsafe extern "C" fn update(
        law: *const c_void,
        n: usize,
        stress: *mut f64,
        dstrain: *const f64,
        state: *mut f64,
        err: *mut ErrorBuffer,
    ) -> i32 {
        let law = unsafe { &*(law as *const DruckerPrager) };
        let stress = unsafe { std::slice::from_raw_parts_mut(stress as *mut [f64; 6], n) };
        let dstrain = unsafe { std::slice::from_raw_parts(dstrain as *const [f64; 6], n) };
        let state = unsafe { std::slice::from_raw_parts_mut(state, n) };
        match law.update(stress, dstrain, state) {
            Ok(()) => 0,
            Err(e) => {
                unsafe { (*err).set(&e) };
                1
            }
        }
    }
    unsafe extern "C" fn destroy(law: *mut c_void) {
        drop(unsafe { Box::from_raw(law as *mut DruckerPrager) });
    }
    static PARAMS: [CStrPtr; 4] =
        [CStrPtr(c"young".as_ptr()), CStrPtr(c"poisson".as_ptr()), CStrPtr(c"alpha".as_ptr()), CStrPtr(c"k".as_ptr())];
    static STATE: [CStrPtr; 1] = [CStrPtr(c"gamma_p".as_ptr())];
    static TABLE: LawTableV1 = LawTableV1 {
        abi_version: 1,
        table_size: std::mem::size_of::<LawTableV1>() as u32,
        name: CStrPtr(c"drucker_prager".as_ptr()),
        version: CStrPtr(c"0.1.0".as_ptr()),
        param_count: 4,
        param_names: PARAMS.as_ptr(),
        state_count: 1,
        state_names: STATE.as_ptr(),
        create,
        update,
        destroy,
    };
    #[no_mangle]
    pub extern "C" fn granite_law_table() -> *const LawTableV1 {
        &TABLE
    }
}
