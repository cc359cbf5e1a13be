//! CPU per megabyte and encoder state of each coding at a level, on 8 MB of
//! pose-like JSON fed in 8 KiB pieces (as tower-http does); the state is the
//! peak of Rust allocations while the encoder lives (zstd allocates in C:
//! not seen). `cd bench/compression && cargo run --release`

use std::alloc::{GlobalAlloc, Layout, System};
use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Instant;

struct Counting;
static NOW: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let n = NOW.fetch_add(l.size(), Relaxed) + l.size();
        PEAK.fetch_max(n, Relaxed);
        System.alloc(l)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        NOW.fetch_sub(l.size(), Relaxed);
        System.dealloc(p, l)
    }
}
#[global_allocator]
static A: Counting = Counting;

/// Output that counts bytes and keeps none.
struct Sink(usize);
impl Write for Sink {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0 += b.len();
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn sample_json(len: usize) -> Vec<u8> {
    let mut out = String::with_capacity(len + 256);
    let mut x: u32 = 12345;
    out.push_str("{\"poses\":[");
    while out.len() < len {
        x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let f = f64::from(x >> 8) / f64::from(1u32 << 24) - 0.5;
        out.push_str(&format!("{{\"joint\":\"mixamorig:joint_{}\",\"t\":[{f:.6},{:.6},0.0]}},", x % 4096, f * 0.5));
    }
    out.push_str("{}]}");
    out.into_bytes()
}

fn run(coding: &str, level: u32, json: &[u8]) {
    let base = NOW.load(Relaxed);
    PEAK.store(base, Relaxed);
    let started = Instant::now();
    let out = match coding {
        "zstd" => {
            let mut e = zstd::stream::Encoder::new(Sink(0), level as i32).unwrap();
            for c in json.chunks(8192) {
                e.write_all(c).unwrap();
            }
            e.finish().unwrap().0
        }
        "br" => {
            let mut e = brotli::CompressorWriter::new(Sink(0), 4096, level, 22);
            for c in json.chunks(8192) {
                e.write_all(c).unwrap();
            }
            e.flush().unwrap();
            e.into_inner().0
        }
        _ => {
            let mut e = flate2::write::GzEncoder::new(Sink(0), flate2::Compression::new(level));
            for c in json.chunks(8192) {
                e.write_all(c).unwrap();
            }
            e.finish().unwrap().0
        }
    };
    let secs = started.elapsed().as_secs_f64();
    let state = PEAK.load(Relaxed) - base;
    println!(
        "| {coding} | {level} | {:.1} | {:.1} | {:.0} | {:.1} |",
        secs * 1e3 / (json.len() as f64 / 1e6),
        secs * 1e9 / json.len() as f64,
        state as f64 / 1024.0,
        json.len() as f64 / out as f64
    );
}

fn main() {
    let json = sample_json(8 << 20);
    println!("| coding | level | ms CPU per MB | ns per byte | encoder state (KiB) | ratio |");
    println!("|---|---|---|---|---|---|");
    for (c, l) in [("zstd", 1), ("zstd", 3), ("br", 1), ("br", 4), ("br", 11), ("gzip", 1), ("gzip", 6)] {
        if c == "br" && l == 11 {
            run(c, l, &json[..1 << 20]);
        } else {
            run(c, l, &json);
        }
    }
}
