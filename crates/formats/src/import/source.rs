//! Where an import's bytes come from: memory, or a file read by range.
//!
//! A character file is mostly textures and meshes, which an animation
//! import never reads. So the importers never take a whole file: they ask a
//! [`Source`] for the ranges they need (the GLB header and JSON chunk, then
//! the accessors' bytes), and a file-backed source reads just those with
//! positional reads. A 200 MB GLB whose animations hold 1 MB costs about
//! 1 MB of memory, whatever the size of its images. A memory-backed source
//! hands out zero-copy [`Bytes`] slices of one allocation.
//!
//! A source never opens a path: a file is given to it already open (the
//! server's spooled upload, the CLI's file), so what the importers may read
//! stays decided by their callers.

use std::fs::File;
use std::io;
use std::sync::Arc;

use bytes::Bytes;

/// Bytes the importers read by range (cheap to clone: a shared handle).
#[derive(Debug, Clone)]
pub struct Source {
    data: Data,
    /// Where this source starts in `data`, and its length.
    start: u64,
    len: u64,
}

#[derive(Debug, Clone)]
enum Data {
    Memory(Bytes),
    File(Arc<File>),
}

impl Source {
    /// Bytes in memory.
    pub fn memory(bytes: impl Into<Bytes>) -> Source {
        let bytes = bytes.into();
        let len = bytes.len() as u64;
        Source { data: Data::Memory(bytes), start: 0, len }
    }

    /// The first `len` bytes of an open file, read only where asked.
    pub fn file(file: Arc<File>, len: u64) -> Source {
        Source { data: Data::File(file), start: 0, len }
    }

    /// A whole open file, its length from its metadata.
    ///
    /// # Errors
    /// The metadata cannot be read.
    pub fn open_file(file: File) -> io::Result<Source> {
        let len = file.metadata()?.len();
        Ok(Source::file(Arc::new(file), len))
    }

    pub fn len(&self) -> u64 {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// `len` bytes from `at`, as a source of their own; `None` past the end.
    pub fn slice(&self, at: u64, len: u64) -> Option<Source> {
        let end = at.checked_add(len)?;
        (end <= self.len).then(|| Source { data: self.data.clone(), start: self.start + at, len })
    }

    /// `len` bytes from `at`: a slice of the memory, or one read from the file.
    ///
    /// # Errors
    /// A range past the end (`UnexpectedEof`: callers check ranges first, so
    /// this is a bug or a file cut short under us), or the read failing.
    pub fn read(&self, at: u64, len: usize) -> io::Result<Bytes> {
        let end = at.checked_add(len as u64).filter(|&end| end <= self.len);
        let Some(end) = end else {
            let detail = format!("bytes {at}..+{len} are past the end of a {}-byte source", self.len);
            return Err(io::Error::new(io::ErrorKind::UnexpectedEof, detail));
        };
        match &self.data {
            Data::Memory(bytes) => Ok(bytes.slice((self.start + at) as usize..(self.start + end) as usize)),
            Data::File(file) => {
                let mut buf = vec![0; len];
                read_exact_at(file, &mut buf, self.start + at)?;
                Ok(Bytes::from(buf))
            }
        }
    }

    /// At most the first `max` bytes (format sniffing).
    ///
    /// # Errors
    /// As [`Source::read`].
    pub fn head(&self, max: usize) -> io::Result<Bytes> {
        self.read(0, self.len.min(max as u64) as usize)
    }

    /// Every byte, for formats parsed whole (the caller bounds the length).
    ///
    /// # Errors
    /// As [`Source::read`].
    pub fn read_all(&self) -> io::Result<Bytes> {
        let len = usize::try_from(self.len).map_err(|_| io::Error::other("the source is too large to hold"))?;
        self.read(0, len)
    }
}

impl From<Bytes> for Source {
    fn from(bytes: Bytes) -> Source {
        Source::memory(bytes)
    }
}

impl From<Vec<u8>> for Source {
    fn from(bytes: Vec<u8>) -> Source {
        Source::memory(bytes)
    }
}

/// A positional read: no shared cursor, so clones of one source (and the
/// file's other handles) never disturb each other.
#[cfg(unix)]
fn read_exact_at(file: &File, buf: &mut [u8], at: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, at)
}

#[cfg(windows)]
fn read_exact_at(file: &File, mut buf: &mut [u8], mut at: u64) -> io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, at)? {
            0 => return Err(io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                at += n as u64;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    fn both(bytes: &[u8]) -> [Source; 2] {
        let mut file = tempfile::tempfile().unwrap();
        file.write_all(bytes).unwrap();
        [Source::memory(bytes.to_vec()), Source::open_file(file).unwrap()]
    }

    #[test]
    fn memory_and_file_sources_read_the_same_ranges() {
        let bytes: Vec<u8> = (0..=255u8).cycle().take(10_000).collect();
        for source in both(&bytes) {
            assert_eq!(source.len(), 10_000);
            assert_eq!(&source.read(9_000, 100).unwrap()[..], &bytes[9_000..9_100]);
            let inner = source.slice(1_000, 5_000).unwrap();
            assert_eq!(&inner.read(10, 20).unwrap()[..], &bytes[1_010..1_030]);
            assert_eq!(&inner.read_all().unwrap()[..], &bytes[1_000..6_000]);
            assert_eq!(&inner.head(4).unwrap()[..], &bytes[1_000..1_004]);
            assert_eq!(inner.read(4_990, 11).unwrap_err().kind(), io::ErrorKind::UnexpectedEof);
            assert!(source.slice(9_999, 2).is_none() && source.slice(u64::MAX, 2).is_none());
        }
    }

    #[test]
    fn a_memory_source_hands_out_slices_of_its_allocation() {
        let bytes = Bytes::from(vec![7u8; 100]);
        let source = Source::from(bytes.clone()).slice(10, 50).unwrap();
        assert_eq!(source.read(5, 10).unwrap().as_ptr(), bytes[15..].as_ptr());
    }
}
