//! Graphs at play on the protobuf wire (docs/graphs.md, “Using a graph”):
//! a tick's report as a `GraphReport` message, and a `GraphValue` as the
//! value the graph evaluator takes.

use super::proto::pb;
use anim::graph::{GraphReport, Value};

/// A tick's report (`Pose.graph`): the state, the transition while one
/// blends, and each evaluated blend node's weights in its points' order.
pub fn report_to_proto<C>(report: &GraphReport<'_, C>) -> pb::GraphReport {
    pb::GraphReport {
        state: report.state().to_owned(),
        transition: report.transition().map(|t| pb::GraphTransition {
            from: t.from.to_owned(),
            to: t.to.to_owned(),
            alpha: t.alpha,
        }),
        weights: (report.weights())
            .map(|(node, weights)| {
                let weights = weights.iter().map(|&w| w as f32).collect();
                (node.to_owned(), pb::BlendWeights { weights })
            })
            .collect(),
    }
}

/// A setting's value: a number a float's, a flag a bool's or trigger's;
/// `None` for a message whose oneof is unset.
pub fn value_from_proto(value: &pb::GraphValue) -> Option<Value> {
    match value.value? {
        pb::graph_value::Value::Number(n) => Some(Value::Float(n)),
        pb::graph_value::Value::Flag(b) => Some(Value::Bool(b)),
    }
}
