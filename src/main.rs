//! The `inbetween` binary: flags in, one subcommand run. All logic lives in
//! the library; see `inbetween --help`.

use clap::Parser;

fn main() -> std::process::ExitCode {
    inbetween::cli::Cli::parse().run()
}
