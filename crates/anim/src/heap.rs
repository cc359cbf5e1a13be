//! Heap accounting shared by a clip's parts: each reports the bytes it
//! holds so the service can budget its clip cache.

/// Bytes of a vector's allocation (its capacity, not its length).
pub(crate) fn vec_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}
