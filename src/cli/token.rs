//! `inbetween token`: make a token and the hash the server's configuration
//! holds instead of it (`server::tokens`). The token is printed once and
//! never stored; only its hash goes into `[[tokens]]` or `--token`.

use std::io::{BufRead, Write};

use clap::{Args, Subcommand};

use server::tokens::{Scope, TokenHash, TokenSpec, new_token};

#[derive(Debug, Args)]
pub struct TokenArgs {
    #[command(subcommand)]
    command: TokenCommand,
}

#[derive(Debug, Subcommand)]
enum TokenCommand {
    /// Print a fresh random token, its hash and the configuration entry for it.
    New {
        /// The token's name in the configuration (logs, per-token limits).
        #[arg(long, default_value = "client")]
        name: String,
        /// Its scopes: read, write (implies read) or admin (implies both); comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "read")]
        scopes: Vec<Scope>,
    },
    /// Print the `sha256:<hex>` hash of the token read from standard input
    /// (one line; kept off the command line so it stays out of shell history).
    Hash,
}

pub fn run(args: TokenArgs) -> anyhow::Result<()> {
    let mut out = super::results::Results::buffered();
    match args.command {
        TokenCommand::New { name, scopes } => {
            let token = new_token()?;
            let hash = TokenHash::of(token.as_bytes());
            // Validate as the server will, so the printed entry is one it accepts.
            let spec = TokenSpec { name: name.clone(), scopes: scopes.clone(), hash };
            spec.validate().map_err(anyhow::Error::msg)?;
            let list = scopes.iter().map(|s| format!("\"{}\"", s.as_str())).collect::<Vec<_>>().join(", ");
            let flag = scopes.iter().map(|s| s.as_str()).collect::<Vec<_>>().join("+");
            writeln!(out, "token: {token}")?;
            writeln!(out, "hash:  {hash}")?;
            writeln!(out, "\n# inbetween.toml\n[[tokens]]\nname = \"{name}\"\nscopes = [{list}]\nhash = \"{hash}\"")?;
            writeln!(out, "\n# or: --token {name}:{flag}:{hash}")?;
        }
        TokenCommand::Hash => {
            let mut line = String::new();
            std::io::stdin().lock().read_line(&mut line)?;
            let token = line.trim_end_matches(['\n', '\r']);
            anyhow::ensure!(!token.is_empty(), "no token on standard input");
            writeln!(out, "{}", TokenHash::of(token.as_bytes()))?;
        }
    }
    out.flush()?;
    Ok(())
}
