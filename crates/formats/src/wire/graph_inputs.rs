//! What drives a graph over the wire (docs/graphs.md, “Using a graph”): the
//! `set` control's `parameters`, a sampling request's `inputs`, and the
//! `graph` report a pose or frame carries when asked.
//!
//! Names are resolved against a built graph and every value is checked, not
//! corrected: an unknown name, a value of the wrong type or a float outside
//! the parameter's range is refused with the JSON pointer of the value.

use std::collections::BTreeMap;

use bytes::BufMut;
use serde::{Deserialize, Serialize};

use super::doc::DocError;
use super::float::write_float;
use super::json::write_json_str;
use anim::graph::{Graph, GraphReport, Inputs, SetError, Value};

/// Parameter values by name, as a `set` control or an input carries them.
pub type SetDoc = BTreeMap<String, serde_json::Value>;

/// One input of a sampling request: `set` due at the first tick at or after `time`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputDoc {
    pub time: f64,
    pub set: SetDoc,
}

fn problem(code: &'static str, pointer: String, detail: impl Into<String>) -> DocError {
    DocError { code, pointer, detail: detail.into() }
}

/// RFC 6901: a map key in a pointer.
pub(super) fn escape(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

/// `set`'s values as `(parameter, value)` in name order; `pointer` is the
/// map's place in its message (`/parameters` for a control).
///
/// # Errors
/// `unknown_parameter`, `parameter_type` (a float takes a number, a bool or
/// trigger `true`/`false`), `parameter_out_of_range`, `bad_number`, each at
/// the value's pointer.
pub fn parameters<C>(graph: &Graph<C>, set: &SetDoc, pointer: &str) -> Result<Vec<(usize, Value)>, DocError> {
    set.iter().map(|(name, raw)| parameter(graph, name, raw, &format!("{pointer}/{}", escape(name)))).collect()
}

fn parameter<C>(graph: &Graph<C>, name: &str, raw: &serde_json::Value, at: &str) -> Result<(usize, Value), DocError> {
    let Some(p) = graph.parameter_index(name) else {
        let known: Vec<&str> = graph.parameters().iter().map(|p| p.name.as_str()).collect();
        let detail = format!("parameter '{name}' is not in the graph's parameters ({})", known.join(", "));
        return Err(problem("unknown_parameter", at.to_owned(), detail));
    };
    let value = match raw {
        serde_json::Value::Bool(b) => Value::Bool(*b),
        serde_json::Value::Number(n) => Value::Float(n.as_f64().unwrap_or(f64::NAN)),
        _ => Value::Float(f64::NAN),
    };
    let wrong = |expected: &str| {
        problem("parameter_type", at.to_owned(), format!("parameter '{name}' takes a {expected}, got {raw}"))
    };
    if !(raw.is_boolean() || raw.is_number()) {
        let expected = match graph.check_value(p, Value::Bool(true)) {
            Ok(_) => "boolean",
            Err(_) => "number",
        };
        return Err(wrong(expected));
    }
    graph.check_value(p, value).map(|v| (p, v)).map_err(|e| match e {
        SetError::WrongType { expected } => wrong(if expected == "float" { "number" } else { expected }),
        SetError::OutOfRange { min, max } => problem(
            "parameter_out_of_range",
            at.to_owned(),
            format!("parameter '{name}' is in [{min}, {max}], got {raw}"),
        ),
        other => problem("bad_number", at.to_owned(), other.to_string()),
    })
}

/// A request's `inputs` on the grid at `fps`; `pointer` is the list's
/// place (`/inputs`).
///
/// # Errors
/// A `time` that is not a finite number ≥ 0 (`bad_time`), or a value as
/// [`parameters`] refuses it, at `/inputs/i/set/name`.
pub fn inputs<C>(graph: &Graph<C>, list: &[InputDoc], fps: f64, pointer: &str) -> Result<Inputs, DocError> {
    let mut settings = Vec::new();
    for (i, input) in list.iter().enumerate() {
        let at = format!("{pointer}/{i}");
        if !(input.time.is_finite() && input.time >= 0.0) {
            let detail = format!("an input's time is a finite number of seconds ≥ 0, got {}", input.time);
            return Err(problem("bad_time", format!("{at}/time"), detail));
        }
        for (p, v) in parameters(graph, &input.set, &format!("{at}/set"))? {
            settings.push((input.time, p, v));
        }
    }
    Ok(Inputs::new(fps, settings))
}

/// `,"graph":{"state":…,"transition":{"from","to","alpha"}?,"weights":{node:[w…]}}`:
/// the last tick's report, written as a pose's or frame's trailing member.
pub fn write_report<C>(out: &mut impl BufMut, report: &GraphReport<'_, C>) {
    out.put_slice(b",\"graph\":{\"state\":");
    write_json_str(out, report.state());
    if let Some(t) = report.transition() {
        out.put_slice(b",\"transition\":{\"from\":");
        write_json_str(out, t.from);
        out.put_slice(b",\"to\":");
        write_json_str(out, t.to);
        out.put_slice(b",\"alpha\":");
        write_float(out, t.alpha);
        out.put_u8(b'}');
    }
    out.put_slice(b",\"weights\":{");
    for (i, (node, weights)) in report.weights().enumerate() {
        if i > 0 {
            out.put_u8(b',');
        }
        write_json_str(out, node);
        out.put_slice(b":[");
        for (k, w) in weights.iter().enumerate() {
            if k > 0 {
                out.put_u8(b',');
            }
            write_float(out, *w);
        }
        out.put_u8(b']');
    }
    out.put_slice(b"}}");
}
