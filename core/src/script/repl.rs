//! An interactive session: the script API one statement at a time, with variables and functions
//! kept between inputs, so that a user can run, pause, inspect, change a parameter and resume.

use super::{describe, prepare, RunOptions, ScriptContext};
use crate::error::Result;
use crate::registry::Registry;
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
}

impl ReplSession {
    pub fn new(registry: Registry, options: RunOptions) -> Result<ReplSession> {
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
        let with_functions = self.functions.merge(&ast);
        *self.ctx.ast.lock().unwrap() = Some(Arc::new(with_functions.clone()));
        let result = self.engine.eval_ast_with_scope::<Dynamic>(&mut self.scope, &with_functions);
        self.functions = self.functions.merge(&ast.clone_functions_only());
        match result {
            Ok(v) if v.is_unit() => Outcome::Value(None),
            Ok(v) => Outcome::Value(Some(v.to_string())),
            Err(e) => Outcome::Error(describe(&e)),
        }
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
