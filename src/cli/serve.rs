//! `inbetween serve`: flags, environment and an optional TOML file in; the
//! server (`server::Application`) out. Logging is set up here, not in
//! the library, so tests and embedders keep their own subscriber.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;
use tracing_subscriber::EnvFilter;

use server::Application;
use server::config::{LogFormat, RawConfig};

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// A TOML file of settings (flags and INBETWEEN_* variables override it).
    #[arg(long, env = "INBETWEEN_CONFIG", value_name = "FILE")]
    config: Option<PathBuf>,
    #[command(flatten)]
    settings: RawConfig,
}

pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    let file = args.config.as_deref().map(RawConfig::from_toml_file).transpose()?.unwrap_or_default();
    let config = args.settings.over(file).validate()?;
    init_logging(config.log_format);
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async move {
        let app = Application::build(config).await?;
        // Machine-readable: tests and scripts that spawn the binary parse this line.
        let mut stdout = std::io::stdout();
        // One write call (not one per `format!` piece), so a reader that stops
        // after the first line cannot make the second fail with EPIPE.
        let (http, grpc) = (app.local_addr(), app.grpc_addr());
        let scheme = if app.serves_tls() { "https" } else { "http" };
        let lines =
            format!("inbetween listening on {scheme}://{http}\ninbetween gRPC listening on {scheme}://{grpc}\n");
        stdout.write_all(lines.as_bytes())?;
        stdout.flush()?;
        app.run_until_stopped(shutdown_signal()).await
    })
}

fn init_logging(format: LogFormat) {
    let filter = EnvFilter::try_from_env("INBETWEEN_LOG")
        .or_else(|_| EnvFilter::try_from_default_env())
        .unwrap_or_else(|_| EnvFilter::new("info"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi);
    match format {
        LogFormat::Text => builder.init(),
        LogFormat::Json => builder.json().init(),
    }
}

/// Resolves on Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
}
