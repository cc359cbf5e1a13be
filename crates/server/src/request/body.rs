//! JSON request bodies, decoded for every layer that takes one (REST
//! handlers, the WebSocket opening message, stored broadcasts) with the
//! same refusals.

use crate::error::ApiError;

/// A JSON request body, its type errors pointed at the field.
pub fn parse_json<T: serde::de::DeserializeOwned>(body: &[u8]) -> Result<T, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(body);
    let req = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
        use serde_path_to_error::Segment;
        let pointer: String = e
            .path()
            .iter()
            .map(|s| match s {
                Segment::Seq { index } => format!("/{index}"),
                Segment::Map { key } => format!("/{}", key.replace('~', "~0").replace('/', "~1")),
                Segment::Enum { variant } => format!("/{variant}"),
                Segment::Unknown => String::new(),
            })
            .collect();
        let inner = e.into_inner();
        if inner.is_syntax() || inner.is_eof() {
            ApiError::MalformedJson { pointer, detail: inner.to_string() }
        } else {
            ApiError::invalid("invalid_field", pointer, inner.to_string())
        }
    })?;
    de.end().map_err(|e| ApiError::MalformedJson { pointer: String::new(), detail: e.to_string() })?;
    Ok(req)
}
