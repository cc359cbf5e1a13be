//! Where glTF binary data comes from: the GLB container and buffer URIs.
//!
//! The `gltf` crate's own GLB reader panics on a header length under 12
//! and its URI import reads the filesystem, so both are done here, on the
//! upload's bytes only: a GLB is split with checked arithmetic, a buffer is
//! the BIN chunk or a `data:` URI, and any other URI goes to the caller's
//! [`Resolver`] or is refused. Buffers are decoded lazily, so a texture
//! buffer that no animation reads is never touched.
//!
//! A resolved URI is asked for once and its bytes are shared: every buffer
//! naming it holds a [`Bytes`] slice of the same allocation, never a copy.
//! Every buffer's `byteLength` still counts against
//! [`ImportLimits::max_resolved_bytes`](super::ImportLimits), so a file whose
//! thousands of buffers all name one large part is refused, not scanned.

use std::borrow::Cow;
use std::collections::HashMap;
use std::ops::Deref;

use base64::Engine as _;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use bytes::Bytes;

use super::{ImportError, ImportLimits, Resolver};

/// The chunks of a GLB file.
pub(crate) struct Glb<'a> {
    pub json: &'a [u8],
    pub bin: Option<&'a [u8]>,
}

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Splits a GLB container (glTF 2.0 §4.4): a 12-byte header, a JSON chunk,
/// an optional BIN chunk; later chunks are ignored as the spec says.
pub(crate) fn split_glb(bytes: &[u8]) -> Result<Glb<'_>, ImportError> {
    let bad = |m: String| Err(ImportError::Container(m));
    if bytes.len() < 12 {
        return bad(format!("{} bytes is shorter than the 12-byte GLB header", bytes.len()));
    }
    if &bytes[..4] != b"glTF" {
        return bad("the magic is not 'glTF'".into());
    }
    let version = u32_at(bytes, 4).unwrap_or(0);
    if version != 2 {
        return bad(format!("version {version} is not 2"));
    }
    let length = u32_at(bytes, 8).unwrap_or(0) as usize;
    if length < 12 || length > bytes.len() {
        return bad(format!("the header says {length} bytes, but the file has {}", bytes.len()));
    }
    let bytes = &bytes[..length];
    // A chunk at byte `at`: its type, its data and where the next one starts.
    type Chunk<'b> = Option<(&'b [u8; 4], &'b [u8], usize)>;
    let chunk = |at: usize| -> Result<Chunk, ImportError> {
        if at >= bytes.len() {
            return Ok(None);
        }
        let (Some(len), Some(kind)) = (u32_at(bytes, at), bytes.get(at + 4..at + 8)) else {
            return Err(ImportError::Container(format!("a chunk header at byte {at} is cut off")));
        };
        let start = at + 8;
        let end = start.checked_add(len as usize).filter(|&e| e <= bytes.len()).ok_or_else(|| {
            ImportError::Container(format!("the chunk at byte {at} claims {len} bytes, past the end of the file"))
        })?;
        let kind: &[u8; 4] = kind.try_into().map_err(|_| ImportError::Container("bad chunk header".into()))?;
        // Chunks are 4-byte aligned; a missing final padding is tolerated.
        Ok(Some((kind, &bytes[start..end], end.next_multiple_of(4))))
    };
    let Some((kind, json, next)) = chunk(12)? else {
        return bad("there is no JSON chunk".into());
    };
    if kind != b"JSON" {
        return bad("the first chunk is not JSON".into());
    }
    let bin = match chunk(next)? {
        Some((b"BIN\0", data, _)) => Some(data),
        _ => None,
    };
    Ok(Glb { json, bin })
}

/// The bytes of one loaded buffer: a slice of the GLB's BIN chunk, or a
/// shared slice of a decoded `data:` URI or a resolved part.
enum Held<'a> {
    Borrowed(&'a [u8]),
    Shared(Bytes),
}

impl Deref for Held<'_> {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        match self {
            Held::Borrowed(b) => b,
            Held::Shared(b) => b,
        }
    }
}

/// Lazily resolved buffers of one document.
pub(crate) struct Buffers<'a, 'r> {
    /// `(uri, byteLength)` per buffer.
    decl: Vec<(Option<String>, u64)>,
    bin: Option<&'a [u8]>,
    cache: Vec<Option<Held<'a>>>,
    /// What the resolver answered, by URI: each is asked for once.
    resolved: HashMap<String, Bytes>,
    resolver: Option<Resolver<'r>>,
    /// `byteLength`s of the buffers loaded so far, and their bound.
    held_bytes: u64,
    max_held_bytes: u64,
}

impl<'a, 'r> Buffers<'a, 'r> {
    pub(crate) fn new(
        doc: &::gltf::Document,
        bin: Option<&'a [u8]>,
        resolver: Option<Resolver<'r>>,
        limits: &ImportLimits,
    ) -> Self {
        let decl: Vec<_> = doc.as_json().buffers.iter().map(|b| (b.uri.clone(), b.byte_length.0)).collect();
        let cache = (0..decl.len()).map(|_| None).collect();
        let max_held_bytes = limits.max_resolved_bytes;
        Buffers { decl, bin, cache, resolved: HashMap::new(), resolver, held_bytes: 0, max_held_bytes }
    }

    /// The bytes of buffer `index`, exactly `byteLength` long.
    pub(crate) fn get(&mut self, index: usize) -> Result<&[u8], ImportError> {
        if self.cache[index].is_none() {
            let data = self.load(index)?;
            self.cache[index] = Some(data);
        }
        Ok(self.cache[index].as_deref().unwrap_or(&[]))
    }

    fn load(&mut self, index: usize) -> Result<Held<'a>, ImportError> {
        let (uri, declared) = self.decl[index].clone();
        let data = match uri {
            None if index == 0 => match self.bin {
                Some(bin) => Held::Borrowed(bin),
                None => {
                    return Err(ImportError::InvalidGltf(
                        "buffer 0 has no uri and the file has no GLB BIN chunk".into(),
                    ));
                }
            },
            None => return Err(ImportError::InvalidGltf(format!("buffer {index} has no uri (only buffer 0 may)"))),
            Some(uri) if uri.as_bytes().get(..5).is_some_and(|p| p.eq_ignore_ascii_case(b"data:")) => {
                let decoded = decode_data_uri(&uri).map_err(|detail| ImportError::DataUri { buffer: index, detail })?;
                Held::Shared(Bytes::from(decoded))
            }
            Some(uri) => Held::Shared(self.resolve(index, uri)?),
        };
        if (data.len() as u64) < declared {
            return Err(ImportError::OutOfBounds {
                what: format!("buffer {index}"),
                detail: format!("it declares byteLength {declared} but holds {} bytes", data.len()),
            });
        }
        self.count(declared)?;
        Ok(match data {
            Held::Borrowed(b) => Held::Borrowed(&b[..declared as usize]),
            Held::Shared(b) => Held::Shared(b.slice(..declared as usize)),
        })
    }

    /// The bytes behind an external URI: from the cache, else from the
    /// resolver (once per URI), else refused.
    fn resolve(&mut self, index: usize, uri: String) -> Result<Bytes, ImportError> {
        if let Some(bytes) = self.resolved.get(&uri) {
            return Ok(bytes.clone());
        }
        let Some(resolve) = self.resolver.as_mut() else {
            return Err(ImportError::ExternalUri { buffer: index, uri: shorten(&uri) });
        };
        let bytes =
            resolve(&uri).map_err(|reason| ImportError::UnreadableUri { buffer: index, uri: shorten(&uri), reason })?;
        self.resolved.insert(uri, bytes.clone());
        Ok(bytes)
    }

    /// Counts a loaded buffer's `byteLength` against the import's bound,
    /// even when its bytes are shared with another buffer's.
    fn count(&mut self, declared: u64) -> Result<(), ImportError> {
        self.held_bytes = self.held_bytes.saturating_add(declared);
        if self.held_bytes > self.max_held_bytes {
            return Err(ImportError::ResolvedTooLarge { max: self.max_held_bytes, found: self.held_bytes });
        }
        Ok(())
    }
}

/// At most 100 characters of a URI, for messages.
fn shorten(uri: &str) -> String {
    let mut s: String = uri.chars().take(100).collect();
    if s.len() < uri.len() {
        s.push('…');
    }
    s
}

/// Decodes `data:[<media type>][;base64],<data>` (RFC 2397).
fn decode_data_uri(uri: &str) -> Result<Vec<u8>, String> {
    // The caller checked that `uri` starts with the ASCII `data:`.
    let rest = uri.get(5..).unwrap_or("");
    let comma = rest.find(',').ok_or("there is no ',' before the data")?;
    let (header, payload) = (&rest[..comma], &rest[comma + 1..]);
    let payload: Cow<[u8]> = if payload.contains('%') {
        Cow::Owned(percent_encoding::percent_decode_str(payload).collect())
    } else {
        Cow::Borrowed(payload.as_bytes())
    };
    if header.to_ascii_lowercase().ends_with(";base64") {
        const ENGINE: GeneralPurpose = GeneralPurpose::new(
            &base64::alphabet::STANDARD,
            GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent),
        );
        ENGINE.decode(&payload).map_err(|e| format!("invalid base64: {e}"))
    } else {
        Ok(payload.into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A document whose `count` buffers all name `part.bin`, each declaring
    /// `byte_length` bytes.
    fn shared_part_doc(count: usize, byte_length: u64) -> ::gltf::Document {
        let buffers: Vec<String> =
            (0..count).map(|_| format!(r#"{{"uri": "part.bin", "byteLength": {byte_length}}}"#)).collect();
        let json = format!(r#"{{"asset": {{"version": "2.0"}}, "buffers": [{}]}}"#, buffers.join(","));
        ::gltf::Document::from_json(::gltf::json::deserialize::from_str(&json).unwrap()).unwrap()
    }

    fn limits(max_resolved_bytes: u64) -> ImportLimits {
        ImportLimits { max_resolved_bytes, ..ImportLimits::default() }
    }

    #[test]
    fn buffers_naming_one_part_share_its_bytes_and_ask_once() {
        let part = Bytes::from((0..=255u8).cycle().take(1000).collect::<Vec<u8>>());
        let mut calls = Vec::new();
        let mut resolve = |uri: &str| {
            calls.push(uri.to_owned());
            Ok(part.clone())
        };
        let doc = shared_part_doc(64, 600);
        let mut buffers = Buffers::new(&doc, None, Some(&mut resolve), &limits(64 * 600));
        let starts: Vec<(*const u8, usize)> = (0..64)
            .map(|i| {
                let b = buffers.get(i).unwrap();
                (b.as_ptr(), b.len())
            })
            .collect();
        drop(buffers);
        assert_eq!(calls, ["part.bin"], "the resolver is asked once per distinct name");
        // Every buffer is the part's own allocation, cut to its byteLength.
        assert!(starts.iter().all(|&s| s == (part.as_ptr(), 600)), "{starts:?}");
    }

    #[test]
    fn every_buffers_byte_length_counts_even_when_shared() {
        let part = Bytes::from(vec![7u8; 1000]);
        let mut resolve = |_: &str| Ok(part.clone());
        let doc = shared_part_doc(64, 600);
        // 63 buffers of 600 bytes fit in 63·600; the 64th does not.
        let mut buffers = Buffers::new(&doc, None, Some(&mut resolve), &limits(63 * 600));
        for i in 0..63 {
            buffers.get(i).unwrap();
        }
        let refused = buffers.get(63).map(<[u8]>::len).unwrap_err();
        assert_eq!(refused, ImportError::ResolvedTooLarge { max: 63 * 600, found: 64 * 600 });
        assert_eq!(
            (refused.code(), refused.class()),
            ("resolved_bytes_too_large", crate::import::ErrorClass::TooLarge)
        );
    }
}
