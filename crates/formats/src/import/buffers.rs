//! Where glTF binary data comes from: the GLB container and buffer URIs.
//!
//! The `gltf` crate's own GLB reader panics on a header length under 12
//! and its URI import reads the filesystem, so both are done here, on the
//! upload's [`Source`] only: a GLB is split with checked arithmetic (its
//! header and JSON chunk read, its BIN chunk kept as a range of the source),
//! a buffer is the BIN chunk or a `data:` URI, and any other URI goes to the
//! caller's [`Resolver`] or is refused. Buffers are opened lazily and read by
//! range, so a texture or mesh that no animation reads is never touched, and
//! a file-backed BIN chunk costs only the bytes the accessors read.
//!
//! A resolved URI is asked for once and its source is shared: every buffer
//! naming it holds a range of the same source, never a copy. Every buffer
//! named by a URI still counts its `byteLength` against
//! [`ImportLimits::max_resolved_bytes`](super::ImportLimits), so a file whose
//! thousands of buffers all name one large part is refused, not scanned. The
//! GLB's own BIN chunk is not counted there: it is the file itself, already
//! bounded by [`ImportLimits::max_bytes`](super::ImportLimits), and it can
//! back only buffer 0.

use std::borrow::Cow;
use std::collections::HashMap;

use base64::Engine as _;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use bytes::Bytes;

use super::error::ImportError;
use super::source::Source;
use super::spec::{ImportLimits, Resolver};

/// The chunks of a GLB file: the JSON read into memory, the BIN chunk a
/// range of the source, read later only where accessors point.
pub struct Glb {
    pub json: Bytes,
    pub bin: Option<Source>,
}

fn u32_le(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

/// Splits a GLB container (glTF 2.0 §4.4): a 12-byte header, a JSON chunk,
/// an optional BIN chunk; later chunks are ignored as the spec says. The
/// JSON chunk is held in memory whole, so it is refused over `max_json`
/// bytes before it is read.
pub fn split_glb(source: &Source, max_json: u64) -> Result<Glb, ImportError> {
    let bad = |m: String| Err(ImportError::Container(m));
    if source.len() < 12 {
        return bad(format!("{} bytes is shorter than the 12-byte GLB header", source.len()));
    }
    let header = source.read(0, 12)?;
    if &header[..4] != b"glTF" {
        return bad("the magic is not 'glTF'".into());
    }
    let version = u32_le(&header[4..]);
    if version != 2 {
        return bad(format!("version {version} is not 2"));
    }
    let length = u64::from(u32_le(&header[8..]));
    if length < 12 || length > source.len() {
        return bad(format!("the header says {length} bytes, but the file has {}", source.len()));
    }
    let chunk = |at: u64| chunk_at(source, at, length);
    let Some(json_chunk) = chunk(12)? else {
        return bad("there is no JSON chunk".into());
    };
    if &json_chunk.kind != b"JSON" {
        return bad("the first chunk is not JSON".into());
    }
    if json_chunk.len > max_json {
        return Err(ImportError::DocumentTooLarge {
            what: "the GLB's JSON chunk",
            max: max_json,
            found: json_chunk.len,
        });
    }
    let json = source.read(json_chunk.start, json_chunk.len as usize)?;
    let bin = match chunk(json_chunk.next)? {
        Some(c) if &c.kind == b"BIN\0" => source.slice(c.start, c.len),
        _ => None,
    };
    Ok(Glb { json, bin })
}

/// A GLB chunk: its type, where its data starts, its length and where the
/// next chunk starts.
struct Chunk {
    kind: [u8; 4],
    start: u64,
    len: u64,
    next: u64,
}

/// The chunk at byte `at` of a GLB of `length` bytes; `None` at the end.
fn chunk_at(source: &Source, at: u64, length: u64) -> Result<Option<Chunk>, ImportError> {
    if at >= length {
        return Ok(None);
    }
    if at + 8 > length {
        return Err(ImportError::Container(format!("a chunk header at byte {at} is cut off")));
    }
    let head = source.read(at, 8)?;
    let len = u64::from(u32_le(&head));
    let start = at + 8;
    if start + len > length {
        return Err(ImportError::Container(format!(
            "the chunk at byte {at} claims {len} bytes, past the end of the file"
        )));
    }
    // Chunks are 4-byte aligned; a missing final padding is tolerated.
    Ok(Some(Chunk { kind: [head[4], head[5], head[6], head[7]], start, len, next: (start + len).next_multiple_of(4) }))
}

/// Lazily opened buffers of one document, read by range.
pub struct Buffers<'r> {
    /// `(uri, byteLength)` per buffer.
    decl: Vec<(Option<String>, u64)>,
    bin: Option<Source>,
    /// Each opened buffer: exactly `byteLength` bytes of its source.
    cache: Vec<Option<Source>>,
    /// What the resolver answered, by URI: each is asked for once.
    resolved: HashMap<String, Source>,
    resolver: Option<Resolver<'r>>,
    /// `byteLength`s of the URI buffers opened so far, and their bound.
    held_bytes: u64,
    max_held_bytes: u64,
}

impl<'r> Buffers<'r> {
    pub fn new(
        doc: &::gltf::Document,
        bin: Option<Source>,
        resolver: Option<Resolver<'r>>,
        limits: &ImportLimits,
    ) -> Self {
        let decl: Vec<_> = doc.as_json().buffers.iter().map(|b| (b.uri.clone(), b.byte_length.0)).collect();
        let cache = (0..decl.len()).map(|_| None).collect();
        let max_held_bytes = limits.max_resolved_bytes;
        Buffers { decl, bin, cache, resolved: HashMap::new(), resolver, held_bytes: 0, max_held_bytes }
    }

    /// Buffer `index`, exactly `byteLength` long, opened on first use.
    fn get(&mut self, index: usize) -> Result<&Source, ImportError> {
        if self.cache[index].is_none() {
            let data = self.load(index)?;
            self.cache[index] = Some(data);
        }
        self.cache[index].as_ref().ok_or_else(|| ImportError::InvalidGltf(format!("buffer {index} is missing")))
    }

    /// The length of buffer `index` (its `byteLength`, checked against the
    /// bytes that back it).
    pub fn len(&mut self, index: usize) -> Result<u64, ImportError> {
        Ok(self.get(index)?.len())
    }

    /// `len` bytes of buffer `index` from `at`; the caller has checked the
    /// range against [`Buffers::len`].
    pub fn read(&mut self, index: usize, at: u64, len: usize) -> Result<Bytes, ImportError> {
        Ok(self.get(index)?.read(at, len)?)
    }

    fn load(&mut self, index: usize) -> Result<Source, ImportError> {
        let (uri, declared) = self.decl[index].clone();
        let (data, counted) = match uri {
            None if index == 0 => match &self.bin {
                Some(bin) => (bin.clone(), false),
                None => {
                    return Err(ImportError::InvalidGltf(
                        "buffer 0 has no uri and the file has no GLB BIN chunk".into(),
                    ));
                }
            },
            None => return Err(ImportError::InvalidGltf(format!("buffer {index} has no uri (only buffer 0 may)"))),
            Some(uri) if uri.as_bytes().get(..5).is_some_and(|p| p.eq_ignore_ascii_case(b"data:")) => {
                let decoded = decode_data_uri(&uri).map_err(|detail| ImportError::DataUri { buffer: index, detail })?;
                (Source::memory(decoded), true)
            }
            Some(uri) => (self.resolve(index, uri)?, true),
        };
        let Some(buffer) = data.slice(0, declared) else {
            return Err(ImportError::OutOfBounds {
                what: format!("buffer {index}"),
                detail: format!("it declares byteLength {declared} but holds {} bytes", data.len()),
            });
        };
        if counted {
            self.count(declared)?;
        }
        Ok(buffer)
    }

    /// The source behind an external URI: from the cache, else from the
    /// resolver (once per URI), else refused.
    fn resolve(&mut self, index: usize, uri: String) -> Result<Source, ImportError> {
        if let Some(source) = self.resolved.get(&uri) {
            return Ok(source.clone());
        }
        let Some(resolve) = self.resolver.as_mut() else {
            return Err(ImportError::ExternalUri { buffer: index, uri: shorten(&uri) });
        };
        let source =
            resolve(&uri).map_err(|reason| ImportError::UnreadableUri { buffer: index, uri: shorten(&uri), reason })?;
        self.resolved.insert(uri, source.clone());
        Ok(source)
    }

    /// Counts an opened URI buffer's `byteLength` against the import's
    /// bound, even when its bytes are shared with another buffer's.
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
pub fn decode_data_uri(uri: &str) -> Result<Vec<u8>, String> {
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
            Ok(Source::from(part.clone()))
        };
        let doc = shared_part_doc(64, 600);
        let mut buffers = Buffers::new(&doc, None, Some(&mut resolve), &limits(64 * 600));
        let starts: Vec<(*const u8, usize)> = (0..64)
            .map(|i| {
                let len = buffers.len(i).unwrap();
                let b = buffers.read(i, 0, len as usize).unwrap();
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
        let mut resolve = |_: &str| Ok(Source::from(part.clone()));
        let doc = shared_part_doc(64, 600);
        // 63 buffers of 600 bytes fit in 63·600; the 64th does not.
        let mut buffers = Buffers::new(&doc, None, Some(&mut resolve), &limits(63 * 600));
        for i in 0..63 {
            buffers.len(i).unwrap();
        }
        let refused = buffers.len(63).unwrap_err();
        assert_eq!(refused, ImportError::ResolvedTooLarge { max: 63 * 600, found: 64 * 600 });
        assert_eq!(
            (refused.code(), refused.class()),
            ("resolved_bytes_too_large", crate::import::ErrorClass::TooLarge)
        );
    }

    /// A GLB of a JSON chunk and a BIN chunk, with `tail` bytes after it.
    fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
        let (jlen, blen) = (json.len().next_multiple_of(4), bin.len().next_multiple_of(4));
        let total = 12 + 8 + jlen + 8 + blen;
        let mut out = b"glTF".to_vec();
        for n in [2, total as u32, jlen as u32] {
            out.extend_from_slice(&n.to_le_bytes());
        }
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(json);
        out.resize(20 + jlen, b' ');
        out.extend_from_slice(&(blen as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(bin);
        out.resize(total, 0);
        out
    }

    #[test]
    fn a_glb_split_from_a_file_reads_its_json_and_keeps_its_bin_as_a_range() {
        use std::io::Write;
        let bin: Vec<u8> = (0..=255u8).cycle().take(5000).collect();
        let bytes = glb(br#"{"asset":{"version":"2.0"}}"#, &bin);
        let mut file = tempfile::tempfile().unwrap();
        file.write_all(&bytes).unwrap();
        for source in [Source::from(bytes.clone()), Source::open_file(file).unwrap()] {
            let split = split_glb(&source, 1000).unwrap();
            assert_eq!(&split.json[..27], br#"{"asset":{"version":"2.0"}}"#);
            let got = split.bin.unwrap();
            assert_eq!((got.len(), &got.read(4000, 8).unwrap()[..]), (5000, &bin[4000..4008]));
            let refused = split_glb(&source, 27).map(|_| ()).unwrap_err();
            assert_eq!(refused, ImportError::DocumentTooLarge { what: "the GLB's JSON chunk", max: 27, found: 28 });
        }
    }
}
