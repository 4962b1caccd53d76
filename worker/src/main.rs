//! `relief-worker`: dials a Relief server, registers, and bakes the relief textures the
//! server assigns — with all its cores — until told to stop (SIGINT/SIGTERM: finishes
//! the jobs it holds, then exits).

mod daemon;
mod metrics;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use relief_proto::convert::{MAX_WORKER_NAME_BYTES, MAX_WORKER_SLOTS};

#[derive(Parser)]
#[command(
    name = "relief-worker",
    version,
    about = "Relief's worker: ray-traces relief textures for a server"
)]
pub struct Args {
    /// The server's URL, e.g. http://10.0.0.5:7411.
    #[arg(long, env = "RELIEF_SERVER")]
    server: String,
    /// PEM file of certificates to trust for an `https://` server (e.g. its
    /// self-signed certificate); the system's roots are trusted too.
    #[arg(long, env = "RELIEF_TLS_CA")]
    tls_ca: Option<PathBuf>,
    /// This worker's credential (the server's --worker-token, or its shared --token).
    #[arg(long, env = "RELIEF_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Send --token over plain http:// to a host other than this one (else refused:
    /// anyone on the path could read it).
    #[arg(long, env = "RELIEF_ALLOW_INSECURE")]
    allow_insecure: bool,
    /// Jobs baked at once (each uses every core).
    #[arg(long, env = "RELIEF_SLOTS", default_value = "1", value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_WORKER_SLOTS)))]
    slots: u32,
    /// Name in the server's logs, at most 256 bytes (default: host name and process id).
    #[arg(long, env = "RELIEF_WORKER_NAME", value_parser = worker_name)]
    name: Option<String>,
    /// Where fetched scenes are unpacked (default: under the system's temp dir).
    #[arg(long, env = "RELIEF_SCENE_DIR")]
    scene_dir: Option<PathBuf>,
    /// Serve metrics for Prometheus on this address (`http://ADDR/metrics`; any path
    /// answers): bakes, their time, rays cast. Off by default.
    #[arg(long, env = "RELIEF_METRICS_LISTEN")]
    metrics_listen: Option<std::net::SocketAddr>,
    /// Heartbeat period in milliseconds (keep well under the server's lease).
    #[arg(long, default_value = "1000", value_parser = clap::value_parser!(u64).range(10..=600_000))]
    heartbeat_ms: u64,
}

fn main() -> ExitCode {
    relief_startup::run(|args: Args| {
        let runtime =
            tokio::runtime::Runtime::new().map_err(|e| anyhow::anyhow!("starting the async runtime: {e}"))?;
        runtime.block_on(daemon::run(args))
    })
}

/// A `--name` the server accepts: at most [`MAX_WORKER_NAME_BYTES`].
fn worker_name(name: &str) -> Result<String, String> {
    match name.len() {
        n if n <= MAX_WORKER_NAME_BYTES => Ok(name.to_string()),
        n => Err(format!("{n} bytes; at most {MAX_WORKER_NAME_BYTES}")),
    }
}
