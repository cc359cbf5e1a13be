//! Reading glTF accessors with every offset checked first (glTF 2.0 §3.6).
//!
//! The crate's own readers trust the document; here each accessor's count,
//! stride and offsets are checked against its buffer view and buffer, with
//! overflow-checked arithmetic, before a single value is read or a vector
//! allocated. Sparse accessors are applied on top of their base (or zeros).
//!
//! Only the bytes an accessor's elements occupy are read, never its whole
//! view or buffer, and strided elements are read in windows of at most
//! [`WINDOW_BYTES`], so the memory a read takes is its output plus a window
//! whatever the stride (up to 252 bytes, checked by the crate) and the size
//! of the file behind the buffer.

use ::gltf::accessor::{Accessor, DataType, Dimensions};

use super::buffers::Buffers;
use super::error::ImportError;

/// Most bytes of strided elements read at once from a buffer.
const WINDOW_BYTES: usize = 1 << 20;

/// What the caller expects of an accessor.
pub struct Expect<'s> {
    /// For messages: "animation 2 sampler 0 input".
    pub what: &'s str,
    pub dims: Dimensions,
    /// Accept normalised integer components (rotation outputs, §3.11).
    pub normalized_ints: bool,
    pub max_count: usize,
}

fn dims_name(d: Dimensions) -> &'static str {
    match d {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

/// The accessor's components as `f32`, flat (`count × components`).
///
/// # Errors
/// A type other than expected, a count over the limit, data outside its
/// view or buffer, or a non-finite value.
pub fn read_f32(acc: &Accessor, buffers: &mut Buffers, expect: &Expect) -> Result<Vec<f32>, ImportError> {
    let what = || format!("{} (accessor {})", expect.what, acc.index());
    let layout = Layout::check(acc, expect, &what)?;
    let normalized_int = expect.normalized_ints && acc.normalized() && layout.data_type != DataType::U32;
    if layout.data_type != DataType::F32 && !normalized_int {
        return Err(ImportError::Unsupported(format!(
            "{} has component type {:?}; only FLOAT{} is supported here",
            what(),
            layout.data_type,
            if expect.normalized_ints { " or normalized BYTE/SHORT" } else { "" }
        )));
    }
    let out = read_elements(acc, buffers, &layout, &what, Layout::decode)?;
    if let Some(i) = out.iter().position(|x| !x.is_finite()) {
        return Err(ImportError::NonFinite { what: format!("{} element {}", what(), i / layout.comps) });
    }
    Ok(out)
}

/// The accessor's unsigned integer components as stored, flat: vertex
/// joint indices (`JOINTS_n`: UNSIGNED_BYTE or UNSIGNED_SHORT) and
/// primitive indices (UNSIGNED_BYTE, SHORT or INT). `expect.normalized_ints`
/// is ignored: a normalised accessor is refused.
///
/// # Errors
/// As [`read_f32`], and a float, signed or normalised component type.
pub fn read_uint(acc: &Accessor, buffers: &mut Buffers, expect: &Expect) -> Result<Vec<u32>, ImportError> {
    let what = || format!("{} (accessor {})", expect.what, acc.index());
    let layout = Layout::check(acc, expect, &what)?;
    if !matches!(layout.data_type, DataType::U8 | DataType::U16 | DataType::U32) || acc.normalized() {
        return Err(ImportError::Unsupported(format!(
            "{} has component type {:?}{}; only unsigned integers are supported here",
            what(),
            layout.data_type,
            if acc.normalized() { " (normalized)" } else { "" }
        )));
    }
    read_elements(acc, buffers, &layout, &what, Layout::decode_uint)
}

/// The dense elements (or zeros without a view), then the sparse ones.
fn read_elements<T: Copy + Default>(
    acc: &Accessor,
    buffers: &mut Buffers,
    layout: &Layout,
    what: &dyn Fn() -> String,
    decode: fn(&Layout, &[u8]) -> T,
) -> Result<Vec<T>, ImportError> {
    let mut out = match acc.view() {
        Some(view) => read_dense(acc, &view, buffers, layout, what, decode)?,
        None => vec![T::default(); layout.count * layout.comps],
    };
    if let Some(sparse) = acc.sparse() {
        apply_sparse(&sparse, buffers, layout, &mut out, what, decode)?;
    }
    Ok(out)
}

/// An accessor's elements as checked against what the caller expects:
/// everything the readers need before they touch a byte.
struct Layout {
    data_type: DataType,
    /// Elements (at least 1, at most the caller's `max_count`).
    count: usize,
    /// Components per element.
    comps: usize,
    /// Bytes per component.
    comp_size: usize,
    /// Bytes per element, unpadded.
    elem: usize,
}

impl Layout {
    /// Refuses an accessor of other dimensions, or a count of 0 or over the
    /// limit (the readers check the component type).
    fn check(acc: &Accessor, expect: &Expect, what: &dyn Fn() -> String) -> Result<Layout, ImportError> {
        if acc.dimensions() != expect.dims {
            return Err(ImportError::InvalidGltf(format!(
                "{} is {}, expected {}",
                what(),
                dims_name(acc.dimensions()),
                dims_name(expect.dims)
            )));
        }
        let data_type = acc.data_type();
        let count = acc.count();
        if count == 0 {
            return Err(ImportError::InvalidGltf(format!("{} has count 0", what())));
        }
        if count > expect.max_count {
            return Err(ImportError::TooLarge {
                what: "the keys of one accessor",
                max: expect.max_count as u64,
                found: count as u64,
            });
        }
        let comps = expect.dims.multiplicity();
        let comp_size = data_type.size();
        // Matrices of 1- or 2-byte components have padded columns; only float
        // matrices are read here (MAT4 is only ever read by `read_f32`, never normalized).
        Ok(Layout { data_type, count, comps, comp_size, elem: comps * comp_size })
    }

    /// One component from its little-endian bytes; normalised integers
    /// map to [-1, 1] or [0, 1] (glTF 2.0 §3.11).
    fn decode(&self, b: &[u8]) -> f32 {
        match self.data_type {
            DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            DataType::I8 => (b[0] as i8 as f32 / 127.0).max(-1.0),
            DataType::U8 => b[0] as f32 / 255.0,
            DataType::I16 => (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0),
            DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0,
            DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        }
    }

    /// One unsigned integer component from its little-endian bytes.
    fn decode_uint(&self, b: &[u8]) -> u32 {
        match self.comp_size {
            1 => u32::from(b[0]),
            2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
            _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        }
    }
}

/// The elements stored in the accessor's buffer view, after checking that
/// its stride holds an element and that the last element ends inside it.
fn read_dense<T>(
    acc: &Accessor,
    view: &::gltf::buffer::View,
    buffers: &mut Buffers,
    layout: &Layout,
    what: &dyn Fn() -> String,
    decode: fn(&Layout, &[u8]) -> T,
) -> Result<Vec<T>, ImportError> {
    let Layout { count, comps, comp_size, elem, .. } = *layout;
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(ImportError::InvalidGltf(format!(
            "{}: buffer view {} has byteStride {stride}, smaller than one element ({elem} bytes)",
            what(),
            view.index()
        )));
    }
    let span = view_span(view, buffers, what)?;
    let start = acc.offset();
    // Last byte read: start + stride·(count−1) + elem.
    let end = (count - 1).checked_mul(stride).and_then(|x| x.checked_add(start)).and_then(|x| x.checked_add(elem));
    match end {
        Some(end) if end as u64 <= span.length => {}
        _ => {
            return Err(ImportError::OutOfBounds {
                what: what(),
                detail: format!(
                    "{count} elements of {elem} bytes, stride {stride}, from offset {start} do not fit \
                     in buffer view {} ({} bytes)",
                    view.index(),
                    span.length
                ),
            });
        }
    }
    let mut out = Vec::with_capacity(count * comps);
    // Elements per window: at least one, however wide the stride.
    let per_window = ((WINDOW_BYTES - elem) / stride + 1).max(1);
    let mut first = 0;
    while first < count {
        let n = per_window.min(count - first);
        let from = start + first * stride;
        let bytes = span.read(buffers, from, (n - 1) * stride + elem)?;
        for i in 0..n {
            for c in 0..comps {
                let o = i * stride + c * comp_size;
                out.push(decode(layout, &bytes[o..o + comp_size]));
            }
        }
        first += n;
    }
    Ok(out)
}

/// Overwrites the elements a sparse accessor names (glTF 2.0 §3.6.2.3),
/// after checking both its index and value arrays fit their views and
/// before each write that its index is below the count.
fn apply_sparse<T>(
    sparse: &::gltf::accessor::sparse::Sparse,
    buffers: &mut Buffers,
    layout: &Layout,
    out: &mut [T],
    what: &dyn Fn() -> String,
    decode: fn(&Layout, &[u8]) -> T,
) -> Result<(), ImportError> {
    let Layout { count, comps, comp_size, elem, .. } = *layout;
    let n = sparse.count();
    if n > count {
        return Err(ImportError::InvalidGltf(format!("{}: sparse count {n} exceeds count {count}", what())));
    }
    let indices = sparse.indices();
    let index_size = indices.index_type_size();
    let ispan = view_span(&indices.view(), buffers, what)?;
    let ifrom = indices.offset();
    let fits = |from: usize, size: usize, len: u64| {
        n.checked_mul(size).and_then(|x| x.checked_add(from)).is_some_and(|e| e as u64 <= len)
    };
    if !fits(ifrom, index_size, ispan.length) {
        return Err(ImportError::OutOfBounds {
            what: what(),
            detail: "its sparse indices overrun their buffer view".into(),
        });
    }
    let ibytes = ispan.read(buffers, ifrom, n * index_size)?;
    let values = sparse.values();
    let vspan = view_span(&values.view(), buffers, what)?;
    let vfrom = values.offset();
    if !fits(vfrom, elem, vspan.length) {
        return Err(ImportError::OutOfBounds {
            what: what(),
            detail: "its sparse values overrun their buffer view".into(),
        });
    }
    let vbytes = vspan.read(buffers, vfrom, n * elem)?;
    for k in 0..n {
        let b = &ibytes[k * index_size..];
        let target = match index_size {
            1 => b[0] as usize,
            2 => u16::from_le_bytes([b[0], b[1]]) as usize,
            _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
        };
        if target >= count {
            return Err(ImportError::OutOfBounds {
                what: what(),
                detail: format!("sparse index {target} is not below count {count}"),
            });
        }
        for c in 0..comps {
            let o = k * elem + c * comp_size;
            out[target * comps + c] = decode(layout, &vbytes[o..o + comp_size]);
        }
    }
    Ok(())
}

/// A buffer view's bytes whole (an embedded image), checked against its
/// buffer first.
pub fn read_view(view: &::gltf::buffer::View, buffers: &mut Buffers, what: &str) -> Result<bytes::Bytes, ImportError> {
    let span = view_span(view, buffers, &|| what.to_owned())?;
    span.read(buffers, 0, span.length as usize)
}

/// Where a buffer view lies: its buffer, and its offset and length there.
struct Span {
    buffer: usize,
    offset: u64,
    length: u64,
}

impl Span {
    /// `len` bytes of the view from `at`; the caller has checked the range
    /// against `length`.
    fn read(&self, buffers: &mut Buffers, at: usize, len: usize) -> Result<bytes::Bytes, ImportError> {
        buffers.read(self.buffer, self.offset + at as u64, len)
    }
}

/// A buffer view, checked against its buffer (which is opened, not read).
fn view_span(
    view: &::gltf::buffer::View,
    buffers: &mut Buffers,
    what: &dyn Fn() -> String,
) -> Result<Span, ImportError> {
    let buffer = view.buffer().index();
    let buffer_len = buffers.len(buffer)?;
    let (offset, length) = (view.offset() as u64, view.length() as u64);
    match offset.checked_add(length) {
        Some(end) if end <= buffer_len => Ok(Span { buffer, offset, length }),
        _ => Err(ImportError::OutOfBounds {
            what: what(),
            detail: format!(
                "buffer view {} spans bytes {offset}..+{length} of buffer {buffer}, which has {buffer_len} bytes",
                view.index(),
            ),
        }),
    }
}

trait IndexTypeSize {
    fn index_type_size(&self) -> usize;
}

impl IndexTypeSize for ::gltf::accessor::sparse::Indices<'_> {
    fn index_type_size(&self) -> usize {
        match self.index_type() {
            ::gltf::accessor::sparse::IndexType::U8 => 1,
            ::gltf::accessor::sparse::IndexType::U16 => 2,
            ::gltf::accessor::sparse::IndexType::U32 => 4,
        }
    }
}
