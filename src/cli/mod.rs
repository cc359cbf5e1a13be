//! Command-line entry points, one file per subcommand.
//!
//! Subcommands print their results through [`Results`]: when the reader of
//! standard output leaves early (`inbetween import … | head -c 10`), the
//! write fails with `EPIPE` (Rust ignores `SIGPIPE`), [`Results`] remembers
//! it, and [`Cli::run`] ends quietly with success, as `cat` or `grep` would,
//! instead of reporting "Broken pipe" or panicking in `println!`. Only
//! results go through it: `serve`'s address lines are written as before, so
//! a server whose stdout is gone still says why it stopped.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use results::Results;

mod import;
mod load;
mod results;
mod sample;
mod serve;
mod token;

#[derive(Debug, Parser)]
#[command(name = "inbetween", version, about = "Keyframes in, inbetweens out: a keyframe-animation server and tools.")]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Sample a clip file offline and print its poses as JSON.
    Sample(sample::SampleArgs),
    /// Serve the REST API on the embedded clip store (see docs/api.md).
    Serve(Box<serve::ServeArgs>),
    /// Import a glTF, GLB or BVH file: print clip documents or upload them.
    Import(import::ImportArgs),
    /// Make API tokens and the hashes the server's configuration holds.
    Token(token::TokenArgs),
    /// Load a running server (loopback only by default) and report throughput, latency and stream lateness.
    Load(Box<load::LoadArgs>),
    /// Watch a WebSocket stream of a clip or a composed motion; send controls from stdin or `--at`.
    Watch(Box<::load::watch::WatchArgs>),
    /// The bare sender `load --floor` runs as its own process (reads a frame on stdin).
    #[command(hide = true)]
    LoadFloor(load::FloorArgs),
}

impl Cli {
    pub fn run(self) -> ExitCode {
        let result = match self.command {
            Command::Sample(args) => sample::run(args),
            Command::Serve(args) => serve::run(*args),
            Command::Import(args) => import::run(args),
            Command::Token(args) => token::run(args),
            Command::Load(args) => load::run(*args),
            Command::Watch(args) => ::load::watch::run(*args, Results::lines()),
            Command::LoadFloor(args) => load::run_floor(args),
        };
        match result {
            Ok(()) => ExitCode::SUCCESS,
            // Whatever failed after the reader left was only its consequence.
            Err(_) if results::stdout_closed() => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("inbetween: {e:#}");
                ExitCode::FAILURE
            }
        }
    }
}
