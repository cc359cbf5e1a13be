//! The `inbetween` binary: flags in, one subcommand run (`cli`). The work
//! lives in the workspace's crates; see `inbetween --help`.

use clap::Parser;

mod cli;

/// mimalloc instead of glibc's malloc: the server allocates and frees a
/// response body or a frame per request on two threads, where glibc spent
/// ~10% of the pose route's CPU (`malloc_consolidate`, `_int_free`).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    cli::Cli::parse().run()
}
