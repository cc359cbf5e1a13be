//! Command-line entry points, one file per subcommand.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod import;
mod load;
mod sample;
mod serve;
mod token;
mod watch;

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
    /// Serve the REST API on the embedded clip store (see README, "REST API").
    Serve(Box<serve::ServeArgs>),
    /// Import a glTF, GLB or BVH file: print clip documents or upload them.
    Import(import::ImportArgs),
    /// Make API tokens and the hashes the server's configuration holds.
    Token(token::TokenArgs),
    /// Load a running server (loopback only by default) and report throughput, latency and stream lateness.
    Load(Box<load::LoadArgs>),
    /// Watch a WebSocket stream of a clip or a composed motion; send controls from stdin or `--at`.
    Watch(Box<watch::WatchArgs>),
}

impl Cli {
    pub fn run(self) -> ExitCode {
        let result = match self.command {
            Command::Sample(args) => sample::run(args),
            Command::Serve(args) => serve::run(*args),
            Command::Import(args) => import::run(args),
            Command::Token(args) => token::run(args),
            Command::Load(args) => load::run(*args),
            Command::Watch(args) => watch::run(*args),
        };
        match result {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("inbetween: {e:#}");
                ExitCode::FAILURE
            }
        }
    }
}
