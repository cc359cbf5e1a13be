//! Test support for this crate's tests and the workspace's suites (not part of
//! the API): a real file changed in one place, so that a test breaks one field
//! of a file the importers otherwise accept, and the image headers the
//! texture checks read.

use base64::Engine as _;

/// `glb` written again with its JSON chunk changed by `edit` (padded to four
/// bytes, as GLB requires); its BIN chunk kept as it is.
///
/// # Panics
/// `glb` is not a GLB whose JSON chunk parses (a test's own file).
pub fn glb_with(glb: &[u8], edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("a GLB header")) as usize;
    let mut doc: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).expect("a GLB's JSON chunk");
    edit(&mut doc);
    let mut json = serde_json::to_vec(&doc).expect("JSON");
    json.resize(json.len().next_multiple_of(4), b' ');
    let bin = &glb[20 + json_len..];
    let mut out = b"glTF".to_vec();
    for n in [2, (20 + json.len() + bin.len()) as u32, json.len() as u32] {
        out.extend_from_slice(&n.to_le_bytes());
    }
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(bin);
    out
}

/// `glb` with its first image replaced by `image`, as a `data:` URI.
///
/// # Panics
/// As [`glb_with`].
pub fn glb_with_image(glb: &[u8], image: &[u8]) -> Vec<u8> {
    let uri = format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(image));
    glb_with(glb, |d| d["images"][0] = serde_json::json!({ "uri": uri }))
}

/// A PNG of `width` × `height`: signature and an IHDR chunk (8-bit RGBA),
/// as much of a file as the header check reads.
pub fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut png = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
    png.extend_from_slice(&[0, 0, 0, 13]);
    png.extend_from_slice(b"IHDR");
    png.extend_from_slice(&width.to_be_bytes());
    png.extend_from_slice(&height.to_be_bytes());
    png.extend_from_slice(&[8, 6, 0, 0, 0]);
    png.extend_from_slice(&[0, 0, 0, 0]); // CRC, not checked
    png
}

/// A JPEG: SOI, an APP0 segment, then a baseline SOF0 of `width` × `height`.
pub fn jpeg_header(width: u16, height: u16) -> Vec<u8> {
    let mut jpeg = vec![0xFF, 0xD8];
    jpeg.extend_from_slice(&[0xFF, 0xE0, 0, 16, b'J', b'F', b'I', b'F', 0, 1, 1, 0, 0, 1, 0, 1, 0, 0]);
    jpeg.extend_from_slice(&[0xFF, 0xFF]); // a fill byte
    jpeg.extend_from_slice(&[0xFF, 0xC0, 0, 11, 8]);
    jpeg.extend_from_slice(&height.to_be_bytes());
    jpeg.extend_from_slice(&width.to_be_bytes());
    jpeg.extend_from_slice(&[1, 1, 0x11, 0]);
    jpeg
}
