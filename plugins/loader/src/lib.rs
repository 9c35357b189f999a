//! Loading native constitutive-law plugins (see the granite-plugin-abi crate). A library is
//! checked (symbol, ABI version, table size) and then kept loaded for the life of the process:
//! granite never unloads a library, so no law can outlive its code.

use granite_core::error::{GraniteError, Result};
use granite_core::ext::{ConstitutiveLaw, ConstitutiveLawFactory, LawBatch};
use granite_core::params::{ParamSpec, Params};
use granite_core::registry::Registry;
use granite_plugin_abi::{ErrorBuffer, LawTable, LawTableV1, ABI_VERSION};
use std::ffi::{c_void, CStr};
use std::path::Path;
use std::sync::Arc;

/// Static strings of a plugin table (the library is never unloaded).
unsafe fn text(p: granite_plugin_abi::CStrPtr) -> &'static str {
    if p.0.is_null() {
        return "";
    }
    let s: &'static CStr = unsafe { CStr::from_ptr(p.0) };
    s.to_str().unwrap_or("")
}

/// The functions of a plugin table, whatever its ABI version.
#[derive(Clone, Copy)]
struct Functions {
    create: unsafe extern "C" fn(*const f64, usize, *mut ErrorBuffer) -> *mut c_void,
    update: unsafe extern "C" fn(*const c_void, usize, *mut f64, *const f64, *mut f64, *mut ErrorBuffer) -> i32,
    destroy: unsafe extern "C" fn(*mut c_void),
    /// Absent from version-1 tables.
    wave_speed: Option<unsafe extern "C" fn(*const c_void, f64) -> f64>,
}

/// A loaded law plugin: its table and where it came from.
pub struct NativeLawFactory {
    table: Functions,
    name: String,
    version: String,
    library: String,
    specs: Vec<ParamSpec>,
    state_names: Vec<&'static str>,
}

/// Loads a plugin library and registers its law; returns the law's name and version. A law
/// whose name the registry already has (a built-in law, another plugin's) is refused unless
/// `replace` is set.
///
/// The library's code runs in this process with the user's rights, as any program they start:
/// load only libraries you trust. Panics inside it are caught (each export of `export_law!`
/// catches them), unless it was built with `panic = "abort"`, which ends the process.
pub fn load_plugin(path: &Path, registry: &mut Registry, replace: bool) -> Result<(String, String)> {
    let library = path.display().to_string();
    let lib = unsafe { libloading::Library::new(path) }
        .map_err(|e| GraniteError::Other(format!("plugin {library}: cannot load the library: {e}")))?;
    // Never unloaded: laws built from it must keep their code.
    let lib: &'static libloading::Library = Box::leak(Box::new(lib));
    let entry: libloading::Symbol<'static, unsafe extern "C" fn() -> *const LawTable> = unsafe {
        lib.get(b"granite_law_table\0")
    }
    .map_err(|e| {
        GraniteError::Other(format!("plugin {library}: no `granite_law_table` symbol ({e}): not a granite law plugin"))
    })?;
    let table = unsafe { entry() };
    if table.is_null() {
        return Err(GraniteError::Other(format!("plugin {library}: `granite_law_table` returned null")));
    }
    // The library as the file it is, whatever path named it: loading it again (a script run twice
    // in a REPL, two scripts that load it) finds its own law and does nothing.
    let file = std::fs::canonicalize(path).map_or_else(|_| library.clone(), |p| p.display().to_string());
    // SAFETY: the library exported the table as a static of the plugin ABI.
    unsafe { register(table, &library, file, registry, replace) }
}

/// Registers the law of a plugin table (what `load_plugin` found in a library).
///
/// # Safety
/// `table` points to a static table laid out as `granite_plugin_abi` says for the version it
/// declares, whose strings and functions live as long as the process.
pub unsafe fn register_table(
    table: *const LawTable,
    library: String,
    registry: &mut Registry,
    replace: bool,
) -> Result<(String, String)> {
    // SAFETY: as the caller promised.
    unsafe { register(table, &library, library.clone(), registry, replace) }
}

/// [`register_table`] of a table from the library file `file` (its canonical path, which the law
/// reports as its description), named `library` in messages.
///
/// # Safety
/// As [`register_table`].
unsafe fn register(
    table: *const LawTable,
    library: &str,
    file: String,
    registry: &mut Registry,
    replace: bool,
) -> Result<(String, String)> {
    // Every version's table starts with version 1's fields (the version and size first); what
    // came later is read only from a table that declares its version.
    let head: &'static LawTableV1 = unsafe { &*(table as *const LawTableV1) };
    let (abi, size) = (head.abi_version, head.table_size as usize);
    let expected = match abi {
        1 => std::mem::size_of::<LawTableV1>(),
        2 | ABI_VERSION => std::mem::size_of::<LawTable>(),
        _ => {
            return Err(GraniteError::Other(format!(
                "plugin {library}: built for plugin ABI version {abi}, this granite reads versions 1 to {ABI_VERSION}: rebuild it against granite-plugin-abi"
            )))
        }
    };
    if size != expected {
        return Err(GraniteError::Other(format!(
            "plugin {library}: its law table (ABI version {abi}) has {size} bytes, granite expects {expected}"
        )));
    }
    let wave_speed = (abi >= 2).then(|| unsafe { (*table).wave_speed });
    let functions = Functions { create: head.create, update: head.update, destroy: head.destroy, wave_speed };
    let table = head;
    let name = unsafe { text(table.name) }.to_string();
    let version = unsafe { text(table.version) }.to_string();
    if name.is_empty() {
        return Err(GraniteError::Other(format!("plugin {library}: the law has no name")));
    }
    let list = |ptr: *const granite_plugin_abi::CStrPtr, n: usize, what: &str| -> Result<Vec<&'static str>> {
        if ptr.is_null() {
            return match n {
                0 => Ok(Vec::new()),
                _ => Err(GraniteError::Other(format!(
                    "plugin {library}: {n} {what} declared and no list of their names"
                ))),
            };
        }
        if abi >= 3 {
            // The list ends with a null pointer: its names are read up to it, never past the
            // declared count, so a count larger than the list is found before anything is read
            // beyond it.
            let named = (0..=n).find(|&k| unsafe { (*ptr.add(k)).0.is_null() });
            if named != Some(n) {
                let held = named.map_or(format!("more than {n}"), |k| k.to_string());
                return Err(GraniteError::Other(format!(
                    "plugin {library}: its table declares {n} {what} and names {held}: a table not made by \
                     granite_plugin_abi::export_law!, or a damaged one"
                )));
            }
        }
        Ok((0..n).map(|k| unsafe { text(*ptr.add(k)) }).collect())
    };
    let specs = list(table.param_names, table.param_count, "parameters")?
        .into_iter()
        .map(|p| ParamSpec::required(p, "a parameter of the plugin law"))
        .collect();
    let state_names = list(table.state_names, table.state_count, "state variables")?;
    if let Ok(existing) = registry.law_factory(&name) {
        if existing.description() == file {
            return Ok((name, version));
        }
        if !replace {
            return Err(GraniteError::Other(format!(
                "plugin {library}: a law named `{}` is already registered ({}); a plugin does not replace a law \
                 silently: rename the plugin's law, or load it with load_plugin(path, #{{ replace: true }})",
                existing.name(),
                existing.description()
            )));
        }
        let old = existing.name().to_string();
        registry.remove_law(&old);
    }
    registry.add_law(Arc::new(NativeLawFactory {
        table: functions,
        name: name.clone(),
        version: version.clone(),
        library: file,
        specs,
        state_names,
    }));
    Ok((name, version))
}

impl ConstitutiveLawFactory for NativeLawFactory {
    fn name(&self) -> &str {
        &self.name
    }
    fn param_specs(&self) -> &[ParamSpec] {
        &self.specs
    }
    fn description(&self) -> &str {
        &self.library
    }
    fn build(&self, params: Params) -> Result<Box<dyn ConstitutiveLaw>> {
        let values: Vec<f64> = self.specs.iter().map(|s| params.get(s.name)).collect();
        let mut err = ErrorBuffer { text: [0; 512], len: 0 };
        let law = unsafe { (self.table.create)(values.as_ptr(), values.len(), &mut err) };
        if law.is_null() {
            return Err(GraniteError::Other(format!("plugin {} (law {}): {}", self.library, self.name, err.message())));
        }
        Ok(Box::new(NativeLaw {
            table: self.table,
            law: LawPtr(law),
            name: self.name.clone(),
            library: format!("{} {}", self.library, self.version),
            params,
            state_names: self.state_names.clone(),
        }))
    }
}

struct LawPtr(*mut c_void);
// The plugin contract: a law object may be used from several threads at once (update is
// called on disjoint batches), as built-in laws are.
unsafe impl Send for LawPtr {}
unsafe impl Sync for LawPtr {}

struct NativeLaw {
    table: Functions,
    law: LawPtr,
    name: String,
    library: String,
    params: Params,
    state_names: Vec<&'static str>,
}

impl Drop for NativeLaw {
    fn drop(&mut self) {
        unsafe { (self.table.destroy)(self.law.0) };
    }
}

impl ConstitutiveLaw for NativeLaw {
    fn name(&self) -> &str {
        &self.name
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn state_names(&self) -> &[&'static str] {
        &self.state_names
    }
    fn wave_speed(&self, density: f64) -> Option<f64> {
        let f = self.table.wave_speed?;
        let c = unsafe { f(self.law.0, density) };
        (c > 0.0 && c.is_finite()).then_some(c)
    }
    fn update(&self, batch: LawBatch<'_>) -> Result<()> {
        let n = batch.len();
        let mut err = ErrorBuffer { text: [0; 512], len: 0 };
        let code = unsafe {
            (self.table.update)(
                self.law.0,
                n,
                batch.stress.as_mut_ptr() as *mut f64,
                batch.dstrain.as_ptr() as *const f64,
                batch.state.as_mut_ptr(),
                &mut err,
            )
        };
        if code != 0 {
            return Err(GraniteError::Other(format!("plugin {} (law {}): {}", self.library, self.name, err.message())));
        }
        Ok(())
    }
}
