//! The kind and size of an embedded texture, read from its header alone
//! (PNG's IHDR, JPEG's SOF marker), so an image that would decode to a
//! gigabyte (a small PNG declaring 16,000 × 16,000) is refused before any
//! viewer decodes it. Nothing here decodes pixels.

/// What a texture's header says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageHeader {
    pub mime_type: &'static str,
    pub width: u32,
    pub height: u32,
}

impl ImageHeader {
    /// Pixels the image decodes to.
    pub fn pixels(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height)
    }
}

/// Why a texture's header could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeaderError {
    /// Neither PNG's nor JPEG's signature.
    NotPngOrJpeg,
    /// The signature of one, with a header cut short or malformed.
    Malformed(&'static str),
}

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

/// The header of a PNG or JPEG file.
///
/// # Errors
/// [`HeaderError`] when `bytes` is neither, or its header is malformed
/// (PNG: no IHDR first, or a zero size; JPEG: no SOF before the scan, or a
/// segment running past the end).
pub fn read_header(bytes: &[u8]) -> Result<ImageHeader, HeaderError> {
    if bytes.starts_with(&PNG_SIGNATURE) {
        png(bytes)
    } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
        jpeg(bytes)
    } else {
        Err(HeaderError::NotPngOrJpeg)
    }
}

/// Signature, then the first chunk: length 13, type `IHDR`, width, height.
fn png(bytes: &[u8]) -> Result<ImageHeader, HeaderError> {
    let ihdr = bytes.get(8..24).ok_or(HeaderError::Malformed("a PNG cut short before its IHDR"))?;
    if ihdr[..8] != [0, 0, 0, 13, b'I', b'H', b'D', b'R'] {
        return Err(HeaderError::Malformed("a PNG whose first chunk is not IHDR"));
    }
    let width = u32::from_be_bytes([ihdr[8], ihdr[9], ihdr[10], ihdr[11]]);
    let height = u32::from_be_bytes([ihdr[12], ihdr[13], ihdr[14], ihdr[15]]);
    if width == 0 || height == 0 {
        return Err(HeaderError::Malformed("a PNG of zero width or height"));
    }
    Ok(ImageHeader { mime_type: "image/png", width, height })
}

/// Segments after SOI until a start-of-frame (SOF0–SOF15 but DHT, JPG and
/// DAC): its height and width. Fill bytes (`FF FF`) and standalone markers
/// (RSTn, TEM) carry no length.
fn jpeg(bytes: &[u8]) -> Result<ImageHeader, HeaderError> {
    const CUT: HeaderError = HeaderError::Malformed("a JPEG that ends before its frame header (SOF)");
    let mut at = 2;
    loop {
        if *bytes.get(at).ok_or(CUT)? != 0xFF {
            return Err(HeaderError::Malformed("a JPEG segment that does not start with a marker"));
        }
        let marker = *bytes.get(at + 1).ok_or(CUT)?;
        match marker {
            0xFF => {
                at += 1;
                continue;
            }
            0x01 | 0xD0..=0xD7 => {
                at += 2;
                continue;
            }
            0xD9 | 0xDA => return Err(HeaderError::Malformed("a JPEG whose scan comes before a frame header (SOF)")),
            _ => {}
        }
        let length = usize::from(u16::from_be_bytes([*bytes.get(at + 2).ok_or(CUT)?, *bytes.get(at + 3).ok_or(CUT)?]));
        if length < 2 {
            return Err(HeaderError::Malformed("a JPEG segment shorter than its length field"));
        }
        if matches!(marker, 0xC0..=0xCF) && !matches!(marker, 0xC4 | 0xC8 | 0xCC) {
            let sof = bytes.get(at + 4..at + 9).ok_or(CUT)?;
            let height = u32::from(u16::from_be_bytes([sof[1], sof[2]]));
            let width = u32::from(u16::from_be_bytes([sof[3], sof[4]]));
            if width == 0 || height == 0 {
                // A height of 0 defers to a DNL marker: no size to check up front.
                return Err(HeaderError::Malformed("a JPEG frame header of zero width or height"));
            }
            return Ok(ImageHeader { mime_type: "image/jpeg", width, height });
        }
        at += 2 + length;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{jpeg_header, png_header};

    #[test]
    fn png_and_jpeg_sizes_come_from_their_headers() {
        let png = read_header(&png_header(16_000, 16_000)).unwrap();
        assert_eq!((png.mime_type, png.width, png.height, png.pixels()), ("image/png", 16_000, 16_000, 256_000_000));
        let jpeg = read_header(&jpeg_header(640, 480)).unwrap();
        assert_eq!((jpeg.mime_type, jpeg.width, jpeg.height), ("image/jpeg", 640, 480));
    }

    #[test]
    fn malformed_headers_are_told_apart_from_other_formats() {
        assert_eq!(read_header(b"GIF89a......"), Err(HeaderError::NotPngOrJpeg));
        assert_eq!(read_header(&[]), Err(HeaderError::NotPngOrJpeg));
        let png = png_header(4, 4);
        assert!(matches!(read_header(&png[..20]), Err(HeaderError::Malformed(_))), "cut inside IHDR");
        let mut not_ihdr = png.clone();
        not_ihdr[12..16].copy_from_slice(b"IDAT");
        assert!(matches!(read_header(&not_ihdr), Err(HeaderError::Malformed(_))));
        assert!(matches!(read_header(&png_header(0, 4)), Err(HeaderError::Malformed(_))));
        let jpeg = jpeg_header(8, 8);
        for cut in [3, 6, 21, 26] {
            assert!(matches!(read_header(&jpeg[..cut]), Err(HeaderError::Malformed(_))), "cut at {cut}");
        }
        let mut scan_first = jpeg[..2].to_vec();
        scan_first.extend_from_slice(&[0xFF, 0xDA, 0, 2]);
        assert!(matches!(read_header(&scan_first), Err(HeaderError::Malformed(_))));
        let mut zero_length = jpeg[..2].to_vec();
        zero_length.extend_from_slice(&[0xFF, 0xE0, 0, 0]);
        assert!(matches!(read_header(&zero_length), Err(HeaderError::Malformed(_))));
        // A segment whose length runs past the end of the file.
        let mut long = jpeg[..2].to_vec();
        long.extend_from_slice(&[0xFF, 0xE0, 0xFF, 0xF0, 0, 0]);
        assert!(matches!(read_header(&long), Err(HeaderError::Malformed(_))));
    }
}
