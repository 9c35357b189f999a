//! An interactive session: the script API one statement at a time, with variables and functions
//! kept between inputs, so that a user can run, pause, inspect, change a parameter and resume.

use super::{describe, prepare, RunOptions, ScriptContext};
use granite_core::error::Result;
use granite_core::registry::Registry;
use rhai::{Dynamic, Engine, Scope, AST};
use std::sync::Arc;

pub struct ReplSession {
    engine: Arc<Engine>,
    scope: Scope<'static>,
    /// Functions defined so far: every later input can call them.
    functions: AST,
    ctx: Arc<ScriptContext>,
}

/// What became of one input.
#[derive(Debug)]
pub enum Outcome {
    /// Evaluated; the value, unless it was `()`.
    Value(Option<String>),
    /// The input is not finished yet (an open block, bracket or string): read another line.
    Incomplete,
    /// A syntax or run-time error, with its position; nothing of the input took effect
    /// beyond the statements before the failing one.
    Error(String),
    /// Stopped by Ctrl-C (any run paused first), with where: what the user asked for, not a
    /// failure.
    Interrupted(String),
}

impl ReplSession {
    /// A session; each simulation it makes writes into its own `simN/` folder of the output folder.
    pub fn new(registry: Registry, options: RunOptions) -> Result<ReplSession> {
        let options = RunOptions { folder_per_simulation: true, ..options };
        let (ctx, engine) = prepare(registry, options)?;
        Ok(ReplSession { engine, scope: Scope::new(), functions: AST::empty(), ctx })
    }

    /// Evaluates one input (one or more statements). With `may_continue`, an input that stops in
    /// the middle of a block or bracket asks for more lines instead of failing.
    pub fn eval(&mut self, input: &str, may_continue: bool) -> Outcome {
        let ast = match self.engine.compile_with_scope(&self.scope, input) {
            Ok(ast) => ast,
            Err(e) if may_continue && stops_at_end(&e, input) => return Outcome::Incomplete,
            Err(e) => {
                let pos = e.position();
                let at = match (pos.line(), pos.position()) {
                    (Some(l), Some(c)) => format!("line {l}, column {c}: "),
                    (Some(l), None) => format!("line {l}: "),
                    _ => String::new(),
                };
                return Outcome::Error(format!("syntax error: {at}{}", e.err_type()));
            }
        };
        match self.run_ast(ast) {
            Ok(v) if v.is_unit() => Outcome::Value(None),
            Ok(v) => Outcome::Value(Some(show(&v))),
            Err(e) if matches!(*e, rhai::EvalAltResult::ErrorTerminated(..)) => {
                Outcome::Interrupted(describe(&e, &self.engine))
            }
            Err(e) => Outcome::Error(describe(&e, &self.engine)),
        }
    }

    /// Evaluates one complete input and hands back its value (for bindings that convert values
    /// themselves); an error or an interruption as the message `eval` gives.
    pub fn eval_value(&mut self, input: &str) -> std::result::Result<Dynamic, String> {
        let ast = self.engine.compile_with_scope(&self.scope, input).map_err(|e| {
            let at = e.position().line().map(|l| format!("line {l}: ")).unwrap_or_default();
            format!("syntax error: {at}{}", e.err_type())
        })?;
        self.run_ast(ast).map_err(|e| describe(&e, &self.engine))
    }

    /// Runs a compiled input with the functions defined so far, Ctrl-C able to stop it, and keeps
    /// the functions it defines.
    fn run_ast(&mut self, ast: AST) -> std::result::Result<Dynamic, Box<rhai::EvalAltResult>> {
        let with_functions = self.functions.merge(&ast);
        *self.ctx.ast.lock().unwrap() = Some(Arc::new(with_functions.clone()));
        super::INTERRUPTIBLE_SINCE.set(Some(self.ctx.pause_requests()));
        let result = self.engine.eval_ast_with_scope::<Dynamic>(&mut self.scope, &with_functions);
        super::INTERRUPTIBLE_SINCE.set(None);
        self.functions = self.functions.merge(&ast.clone_functions_only());
        result
    }

    /// Sets a variable of the session (a new one, or a new value for one it has).
    pub fn set_variable(&mut self, name: &str, value: Dynamic) {
        self.scope.set_value(name.to_string(), value);
    }

    /// A variable's value, if the session has it.
    pub fn variable(&self, name: &str) -> Option<Dynamic> {
        self.scope.get_value::<Dynamic>(name)
    }

    /// A value's type as scripts name it (`DemSim`, `Material`, `map`...).
    pub fn type_name(&self, value: &Dynamic) -> String {
        self.engine.map_type_name(value.type_name()).to_string()
    }

    /// Refuses `--set` names that no `param(...)` evaluated so far declared (as a run does at
    /// its end), with the closest declared names.
    pub fn check_overrides(&self) -> std::result::Result<(), String> {
        self.ctx.check_overrides().map_err(|e| describe(&e, &self.engine))
    }

    /// The script API's calls whose name, forms or documentation contain `filter` (all for an
    /// empty one), one line each: what `:api` prints.
    pub fn api(&self, filter: &str) -> Vec<String> {
        super::api_doc::API
            .iter()
            .filter(|d| d.name.contains(filter) || d.doc.contains(filter) || d.forms.iter().any(|f| f.contains(filter)))
            .map(|d| format!("{:<60} {}", d.forms[0], d.doc))
            .collect()
    }

    /// What `:help NAME` prints: every entry of that name, or the closest names.
    pub fn help(&self, name: &str) -> String {
        let found = super::api_doc::lookup(name);
        if !found.is_empty() {
            return found.iter().map(|d| super::api_doc::help_text(d)).collect::<Vec<_>>().join("\n");
        }
        let word = name.rsplit('.').next().unwrap_or(name);
        format!("no function or property `{name}` in granite's API{}", super::api_doc::did_you_mean(word))
    }

    /// The session's variables and their types (script terms: `DemSim`, `map`...), for completion.
    pub fn variables(&self) -> Vec<(String, String)> {
        self.scope
            .iter()
            .map(|(name, _, value)| (name.to_string(), self.engine.map_type_name(value.type_name()).to_string()))
            .collect()
    }

    /// Makes every run, in the background or not, pause at its next step, keeping the state (Ctrl-C).
    pub fn pause_handle(&self) -> impl Fn() + Send + 'static {
        let ctx = self.ctx.clone();
        move || ctx.request_pause()
    }

    /// Pauses the runs still going in the background and waits for them (leaving the session).
    pub fn finish(&self) {
        self.ctx.finish_background(true);
    }
}

/// A value as the REPL prints it: simulations and materials by what they hold, the rest as Rhai
/// writes it.
pub(crate) fn show(v: &Dynamic) -> String {
    if let Some(sim) = v.clone().try_cast::<super::dem_api::DemHandle>() {
        return sim.describe();
    }
    if let Some(sim) = v.clone().try_cast::<super::mpm_api::SimHandle>() {
        return sim.describe();
    }
    if let Some(m) = v.clone().try_cast::<super::dem_api::DemMaterialHandle>() {
        return format!("DemMaterial(\"{}\")", m.name());
    }
    if let Some(m) = v.clone().try_cast::<super::mpm_api::MaterialHandle>() {
        return format!("Material(\"{}\")", m.name());
    }
    v.to_string()
}

/// Every function of the script API in the script's terms (see [`readable`]), sorted.
pub(crate) fn api_signatures(engine: &rhai::Engine) -> Vec<String> {
    // `to_string` and `to_debug` are how Rhai prints granite's objects, `==` and `!=` how it
    // compares them: not calls of the API.
    const NOT_CALLS: [&str; 4] = ["to_string(", "to_debug(", "==(", "!=("];
    let mut found: Vec<String> = engine
        .gen_fn_signatures(false)
        .iter()
        .filter(|s| !NOT_CALLS.iter().any(|n| s.starts_with(n)))
        .map(|s| readable(s))
        .collect();
    found.sort();
    found.dedup();
    found
}

/// Whether a parse error only says the input stops too early: an open block, bracket or
/// statement at the end of the text (not an error in the middle of it).
fn stops_at_end(e: &rhai::ParseError, input: &str) -> bool {
    if matches!(e.err_type(), rhai::ParseErrorType::UnexpectedEOF) {
        return true;
    }
    let last_line = input.trim_end().lines().count();
    match e.position().line() {
        None => true,
        Some(line) => line > last_line,
    }
}

/// A signature as Rhai's metadata writes it (Rust paths, `Result` wrappers, the receiver as a
/// first parameter) in the script's terms: `DemSim.cloud(DemMaterial, value, value, map) -> int`,
/// `DemSim.time` for a property.
fn readable(signature: &str) -> String {
    const TERMS: [(&str, &str); 10] = [
        ("core::result::Result<", ""),
        (",alloc::boxed::Box<rhai::types::error::EvalAltResult>>", ""),
        ("alloc::vec::Vec<rhai::types::dynamic::Dynamic>", "array"),
        ("alloc::collections::btree::map::BTreeMap<smartstring::SmartString<smartstring::config::LazyCompact>,rhai::types::dynamic::Dynamic>", "map"),
        ("rhai::types::dynamic::Dynamic", "value"),
        ("types::dynamic::Dynamic", "value"),
        ("alloc::string::String", "string"),
        ("granite_script::driver::Handle<granite_run::dem_scene::DemScene>", "DemSim"),
        ("granite_script::driver::Handle<granite_run::mpm_scene::MpmScene>", "MpmSim"),
        ("granite_script::", ""),
    ];
    let mut s = signature.replace("_: ", "");
    for (from, to) in TERMS {
        s = s.replace(from, to);
    }
    s = s
        .replace("mpm_api::MaterialHandle", "Material")
        .replace("dem_api::DemMaterialHandle", "DemMaterial")
        .replace("dem_api::DemWallHandle", "DemWall");
    s = s.replace("i64", "int").replace("f64", "float");
    let s = s.strip_suffix(" -> ()").unwrap_or(&s).to_string();
    // `name(&mut Receiver, rest) -> out` as `Receiver.name(rest) -> out`; getters as properties.
    let Some((name, rest)) = s.split_once('(') else { return s };
    let Some(after) = rest.strip_prefix("&mut ") else { return s };
    let (receiver, rest) = match after.split_once(", ") {
        Some((receiver, rest)) => (receiver, rest.to_string()),
        None => {
            let (receiver, tail) = after.split_once(')').unwrap_or((after, ""));
            (receiver, format!("){tail}"))
        }
    };
    match name.strip_prefix("get$") {
        Some(property) => format!("{receiver}.{property}{}", rest.trim_start_matches(')')),
        None => format!("{receiver}.{name}({rest}"),
    }
}

#[cfg(test)]
mod tests {
    use super::readable;

    #[test]
    fn signatures_read_in_the_scripts_terms() {
        let raw = "cloud(_: &mut DemSim, _: DemMaterial, _: types::dynamic::Dynamic, _: map) -> \
                   core::result::Result<i64,alloc::boxed::Box<rhai::types::error::EvalAltResult>>";
        assert_eq!(readable(raw), "DemSim.cloud(DemMaterial, value, map) -> int");
        assert_eq!(readable("get$dt(_: &mut MpmSim) -> f64"), "MpmSim.dt -> float");
        assert_eq!(
            readable("pause(_: &mut DemSim) -> core::result::Result<(),alloc::boxed::Box<rhai::types::error::EvalAltResult>>"),
            "DemSim.pause()"
        );
        assert_eq!(readable("param(_: &str, _: f64) -> value"), "param(&str, float) -> value");
    }
}

#[cfg(test)]
mod api_table {
    use super::*;

    /// (receiver, name) of every registered function, as the table names them.
    fn registered() -> Vec<(String, String)> {
        let (_, engine) = prepare(Registry::new(), RunOptions::default()).unwrap();
        api_signatures(&engine)
            .iter()
            .map(|s| {
                let head = s.split(['(', ' ']).next().unwrap_or(s);
                match head.split_once('.') {
                    Some((on, name)) => (on.to_string(), name.to_string()),
                    None => (String::new(), head.to_string()),
                }
            })
            .collect()
    }

    #[test]
    fn the_table_names_every_registered_function_and_no_other() {
        let registered = registered();
        for (on, name) in &registered {
            let query = if on.is_empty() { name.clone() } else { format!("{on}.{name}") };
            let found = super::super::api_doc::lookup(&query);
            assert!(
                found.iter().any(|d| d.on == on || (d.on == "sim" && on.ends_with("Sim"))),
                "{query} is not in api_doc::API"
            );
        }
        for d in super::super::api_doc::API {
            let receivers: Vec<&str> = if d.on == "sim" { vec!["MpmSim", "DemSim"] } else { vec![d.on] };
            for on in receivers {
                assert!(
                    registered.iter().any(|(o, n)| o == on && n == d.name),
                    "api_doc::API lists {on}.{} but no such function is registered",
                    d.name
                );
            }
        }
    }
}
