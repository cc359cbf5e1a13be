//! Graphs at play over gRPC (docs/graphs.md): a tick's report as
//! `inbetween.v1.GraphReport`, and a `GraphValue` as the value a graph's
//! parameter is set to.

use anim::graph::{GraphReport, Value};

use super::proto::pb;

/// The report of the last tick a player played (weights in the points' order).
pub fn report_to_proto<C>(report: &GraphReport<'_, C>) -> pb::GraphReport {
    pb::GraphReport {
        state: report.state().to_owned(),
        transition: report.transition().map(|t| pb::GraphTransition {
            from: t.from.to_owned(),
            to: t.to.to_owned(),
            alpha: t.alpha,
        }),
        weights: report
            .weights()
            .map(|(node, w)| (node.to_owned(), pb::BlendWeights { weights: w.iter().map(|&w| w as f32).collect() }))
            .collect(),
    }
}

/// A float's number or a bool's or trigger's flag; `None` for an unset oneof.
pub fn value_from_proto(value: &pb::GraphValue) -> Option<Value> {
    match value.value? {
        pb::graph_value::Value::Number(n) => Some(Value::Float(n)),
        pb::graph_value::Value::Flag(b) => Some(Value::Bool(b)),
    }
}
