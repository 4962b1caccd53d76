//! `relief-server`: scene registry, scheduler, worker registry and result cache behind
//! one gRPC address, with gRPC health checking and server reflection.
//!
//! Prints `relief-server listening on URL` once bound (so `--listen 127.0.0.1:0` can be
//! used and the URL read back); quiet otherwise, `RUST_LOG=info` for more.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use tonic::codec::CompressionEncoding;
use tonic::transport::Server;

use relief_core::scene::SceneLimits;
use relief_proto::bundle::SceneDir;
use relief_proto::limits::{MAX_REQUEST_MESSAGE_BYTES, MAX_TEXTURE_MESSAGE_BYTES, MAX_UPLOAD_MESSAGE_BYTES};
use relief_proto::pb;
use relief_server::connections::{Bounds, CountCalls, accept_within};
use relief_server::identity::{Credentials, Role, read_tokens_file};
use relief_server::service::{Service, Shared, Uploads};
use relief_server::state::{Limits, State};

#[derive(Parser)]
#[command(
    name = "relief-server",
    version,
    about = "Relief's server: schedules relief-texture requests onto workers"
)]
struct Args {
    /// Address to listen on (port 0 picks a free port).
    #[arg(long, env = "RELIEF_LISTEN", default_value = "127.0.0.1:7411")]
    listen: SocketAddr,
    /// A client's credential (`authorization: Bearer TOKEN`): it may upload scenes and
    /// ask for textures, and sees only its own. Repeat for each client.
    #[arg(long = "client-token", value_name = "TOKEN")]
    client_tokens: Vec<String>,
    /// A file of client credentials, one a line (`#` comments).
    #[arg(long, env = "RELIEF_CLIENT_TOKENS_FILE")]
    client_tokens_file: Option<PathBuf>,
    /// A worker's credential: it may take jobs and read the scenes of those it holds.
    /// Repeat for each worker (or pool).
    #[arg(long = "worker-token", value_name = "TOKEN")]
    worker_tokens: Vec<String>,
    /// A file of worker credentials, one a line (`#` comments).
    #[arg(long, env = "RELIEF_WORKER_TOKENS_FILE")]
    worker_tokens_file: Option<PathBuf>,
    /// One secret shared by every client and worker, each able to act as either: only
    /// where every holder is trusted (else give each its own with --client-token and
    /// --worker-token). With no credential at all the server is open to anyone who can
    /// reach it.
    #[arg(long, env = "RELIEF_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// PEM certificate chain: serve TLS (https://) with it and --tls-key.
    #[arg(long, env = "RELIEF_TLS_CERT", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// PEM private key of --tls-cert.
    #[arg(long, env = "RELIEF_TLS_KEY", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Result cache size, MiB.
    #[arg(long, env = "RELIEF_CACHE_MB", default_value = "512", value_parser = clap::value_parser!(u64).range(0..=1 << 20))]
    cache_mb: u64,
    /// A worker silent for this long (ms) loses its jobs to other workers.
    #[arg(long, env = "RELIEF_LEASE_MS", default_value = "5000", value_parser = clap::value_parser!(u64).range(100..=3_600_000))]
    lease_ms: u64,
    /// A request waiting this long (ms) ends with DEADLINE_EXCEEDED (a job nobody waits
    /// for any more is stopped on its worker).
    #[arg(long, env = "RELIEF_JOB_TIMEOUT_MS", default_value = "60000", value_parser = clap::value_parser!(u64).range(100..=86_400_000))]
    job_timeout_ms: u64,
    /// A job whose worker shows no progress (a preview or the final texture) for this
    /// long (ms) is taken back and queued for another worker.
    #[arg(long, env = "RELIEF_JOB_PROGRESS_MS", default_value = "30000", value_parser = clap::value_parser!(u64).range(100..=86_400_000))]
    job_progress_ms: u64,
    /// Most requests waiting at once.
    #[arg(long, env = "RELIEF_MAX_WAITING", default_value = "100000", value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    max_waiting: u64,
    /// Most requests one client credential has waiting at once: one client's flood
    /// cannot take every place.
    #[arg(long, env = "RELIEF_MAX_WAITING_PER_CLIENT", default_value = "2000", value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    max_waiting_per_client: u64,
    /// Most triangles an uploaded scene may have over all its objects, counted from its
    /// files before it is built (generators from their parameters).
    #[arg(long, env = "RELIEF_MAX_SCENE_TRIANGLES", default_value = "8000000", value_parser = clap::value_parser!(u64).range(1..))]
    max_scene_triangles: u64,
    /// Most objects an uploaded scene may have.
    #[arg(long, env = "RELIEF_MAX_SCENE_OBJECTS", default_value = "10000", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    max_scene_objects: u64,
    /// Largest scene upload, MiB, counted decompressed (at most the bundle format's
    /// 512).
    #[arg(long, env = "RELIEF_MAX_UPLOAD_MB", default_value = "128", value_parser = clap::value_parser!(u64).range(1..=512))]
    max_upload_mb: u64,
    /// An upload still arriving after this long (ms) is refused.
    #[arg(long, env = "RELIEF_UPLOAD_TIMEOUT_MS", default_value = "120000", value_parser = clap::value_parser!(u64).range(100..=3_600_000))]
    upload_timeout_ms: u64,
    /// Uploads received at once (each holds up to --max-upload-mb in memory).
    #[arg(long, env = "RELIEF_MAX_UPLOADS", default_value = "4", value_parser = clap::value_parser!(u64).range(1..=1024))]
    max_uploads: u64,
    /// Scenes kept, MiB of their bundles (in memory and again on disk): past it the
    /// least recently used scene no job needs is evicted.
    #[arg(long, env = "RELIEF_SCENE_STORE_MB", default_value = "1024", value_parser = clap::value_parser!(u64).range(1..=1 << 20))]
    scene_store_mb: u64,
    /// Connections open at once (more wait in the kernel's backlog); keep it below the
    /// process's file-descriptor limit.
    #[arg(long, env = "RELIEF_MAX_CONNECTIONS", default_value = "512", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    max_connections: u64,
    /// A connection that has sent nothing (no HTTP/2 preface, no TLS hello) after this
    /// long (ms) is closed.
    #[arg(long, env = "RELIEF_FIRST_BYTES_MS", default_value = "5000", value_parser = clap::value_parser!(u64).range(100..=600_000))]
    first_bytes_ms: u64,
    /// A connection with no call open for this long (ms) is closed: it holds a place
    /// among `--max-connections`. Clients and workers never idle that long (a client
    /// looks at the server's health twice a second, a worker's session is a call).
    #[arg(long, env = "RELIEF_IDLE_CONNECTION_MS", default_value = "60000", value_parser = clap::value_parser!(u64).range(100..=86_400_000))]
    idle_connection_ms: u64,
    /// A connection one of whose answers has waited this long (ms) for its reader to
    /// take its next part is closed: a client that does not read would leave the
    /// encoded texture with the server.
    #[arg(long, env = "RELIEF_STALLED_ANSWER_MS", default_value = "30000", value_parser = clap::value_parser!(u64).range(100..=86_400_000))]
    stalled_answer_ms: u64,
    /// Calls open at once on one connection.
    #[arg(long, env = "RELIEF_MAX_STREAMS", default_value = "256", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    max_streams: u32,
    /// Serve metrics for Prometheus on this address (`http://ADDR/metrics`; any path
    /// answers). Off by default.
    #[arg(long, env = "RELIEF_METRICS_LISTEN")]
    metrics_listen: Option<SocketAddr>,
    /// Where received scenes are unpacked (default: a directory under the system's temp dir).
    #[arg(long, env = "RELIEF_SCENE_DIR")]
    scene_dir: Option<PathBuf>,
}

fn main() -> ExitCode {
    relief_startup::run(|args: Args| {
        let runtime =
            tokio::runtime::Runtime::new().map_err(|e| anyhow::anyhow!("starting the async runtime: {e}"))?;
        let served = runtime.block_on(serve(args));
        // A blocking task still running (a scene still loading) must not hold the
        // exit past the grace: nothing it would produce is wanted any more.
        runtime.shutdown_background();
        served
    })
}

async fn serve(args: Args) -> Result<()> {
    // (Bad credentials fail before anything is created.)
    let credentials = credentials(&args)?;
    // (Held to the end of `serve`: a directory of its own is removed then.)
    let scene_dir = SceneDir::new(args.scene_dir, "relief-server")?;
    std::fs::create_dir_all(scene_dir.path())
        .with_context(|| format!("--scene-dir {}", scene_dir.path().display()))?;
    let lease = Duration::from_millis(args.lease_ms);
    let job_timeout = Duration::from_millis(args.job_timeout_ms);
    let shared = Shared::new(
        State::new(Limits {
            cache_bytes: (args.cache_mb as usize) << 20,
            lease,
            max_waiting: args.max_waiting as usize,
            max_waiting_per_client: args.max_waiting_per_client as usize,
            scene_store_bytes: (args.scene_store_mb as usize) << 20,
            job_progress: Duration::from_millis(args.job_progress_ms),
            job_timeout,
        }),
        scene_dir.path().to_path_buf(),
        SceneLimits {
            max_triangles: args.max_scene_triangles,
            max_objects: args.max_scene_objects as usize,
        },
        Uploads::new(
            (args.max_upload_mb as usize) << 20,
            Duration::from_millis(args.upload_timeout_ms),
            args.max_uploads as usize,
        ),
    );
    // Leases: a silent worker's jobs go back to the queue; jobs past the timeout end;
    // stalled jobs are taken back.
    let watched = shared.clone();
    let progress = Duration::from_millis(args.job_progress_ms);
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(lease.min(job_timeout).min(progress) / 4);
        loop {
            tick.tick().await;
            let mut state = watched.state();
            state.expire_leases();
            state.expire_jobs();
            state.expire_stalled_jobs();
            state.dispatch();
        }
    });
    if !credentials.required() && !args.listen.ip().is_loopback() {
        tracing::warn!(
            "no credential is asked for on {}: anyone who reaches it may use it",
            args.listen
        );
    }
    if let Some(address) = args.metrics_listen {
        let listener = tokio::net::TcpListener::bind(address)
            .await
            .with_context(|| format!("--metrics-listen: binding {address}"))?;
        tracing::info!("metrics on http://{address}/metrics");
        let registry = Arc::new(relief_server::metrics::registry(shared.clone()));
        tokio::spawn(relief_proto::metrics::serve(listener, registry));
    }
    let service = Service(shared);
    let scenes = pb::scenes_server::ScenesServer::new(service.clone())
        .accept_compressed(CompressionEncoding::Zstd)
        .send_compressed(CompressionEncoding::Zstd)
        .max_decoding_message_size(MAX_UPLOAD_MESSAGE_BYTES);
    // (Replies are sent plain: a `zstd_planes` client's planes come compressed by the
    // worker, and for a client of raw planes gRPC's zstd would cost the server a
    // compression per texture and client — work any client could make it do by asking.
    // Such a client pays in bandwidth instead.)
    let impostors = pb::impostors_server::ImpostorsServer::new(service.clone())
        .accept_compressed(CompressionEncoding::Zstd)
        .max_decoding_message_size(MAX_REQUEST_MESSAGE_BYTES)
        .max_encoding_message_size(MAX_TEXTURE_MESSAGE_BYTES);
    let workers = pb::workers_server::WorkersServer::new(service)
        .accept_compressed(CompressionEncoding::Zstd)
        .send_compressed(CompressionEncoding::Zstd)
        .max_decoding_message_size(MAX_TEXTURE_MESSAGE_BYTES);
    let (health, health_service) = tonic_health::server::health_reporter();
    health
        .set_serving::<pb::scenes_server::ScenesServer<Service>>()
        .await;
    health
        .set_serving::<pb::impostors_server::ImpostorsServer<Service>>()
        .await;
    health
        .set_serving::<pb::workers_server::WorkersServer<Service>>()
        .await;
    // Reflection in both versions stock tools speak: `v1` (grpcurl) and `v1alpha`
    // (Python's grpcio-reflection, older grpcurl), of every service served.
    let reflection = || {
        tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
    };
    let reflection_v1 = reflection()
        .build_v1()
        .context("building the reflection service")?;
    let reflection_v1alpha = reflection()
        .build_v1alpha()
        .context("building the reflection service")?;
    // TLS first: a certificate that does not load must fail before the server says
    // it is listening.
    // (Keepalive as clients and workers ping: a peer gone without a word frees its
    // connection, streams and jobs within seconds.)
    let mut builder = Server::builder()
        .max_concurrent_streams(Some(args.max_streams))
        .http2_keepalive_interval(Some(relief_proto::connect::KEEPALIVE_INTERVAL))
        .http2_keepalive_timeout(Some(relief_proto::connect::KEEPALIVE_TIMEOUT));
    if let (Some(cert), Some(key)) = (&args.tls_cert, &args.tls_key) {
        let read =
            |flag: &str, p: &PathBuf| std::fs::read(p).with_context(|| format!("{flag} {}", p.display()));
        let identity =
            tonic::transport::Identity::from_pem(read("--tls-cert", cert)?, read("--tls-key", key)?);
        builder = builder
            .tls_config(tonic::transport::ServerTlsConfig::new().identity(identity))
            .context("--tls-cert/--tls-key: the certificate or key is not usable")?;
    }
    let listener = tokio::net::TcpListener::bind(args.listen)
        .await
        .with_context(|| format!("binding {}", args.listen))?;
    let address = listener.local_addr()?;
    let scheme = if args.tls_cert.is_some() { "https" } else { "http" };
    println!("relief-server listening on {scheme}://{address}");
    let incoming = accept_within(
        listener,
        Bounds {
            max_open: args.max_connections as usize,
            first_bytes_within: Duration::from_millis(args.first_bytes_ms),
            idle_within: Duration::from_millis(args.idle_connection_ms),
            stalled_within: Duration::from_millis(args.stalled_answer_ms),
        },
    );
    // On SIGINT/SIGTERM: stop taking connections and let calls in flight end, but not
    // for ever — a worker's session stream lasts as long as the worker.
    let stop = relief_proto::shutdown::watch();
    let stopped = |mut stop: tokio::sync::watch::Receiver<bool>| async move {
        let _ = stop.wait_for(|stopped| *stopped).await;
    };
    let grace = {
        let stop = stop.clone();
        async move {
            stopped(stop).await;
            tokio::time::sleep(SHUTDOWN_GRACE).await;
            tracing::info!("calls still open {SHUTDOWN_GRACE:?} after the stop signal: closing them");
        }
    };
    let serving = builder
        .layer(CountCalls)
        .add_service(health_service)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha)
        .add_service(tonic::service::interceptor::InterceptedService::new(
            scenes,
            credentials.interceptor(None),
        ))
        .add_service(tonic::service::interceptor::InterceptedService::new(
            impostors,
            credentials.interceptor(Some(Role::Client)),
        ))
        .add_service(tonic::service::interceptor::InterceptedService::new(
            workers,
            credentials.interceptor(Some(Role::Worker)),
        ))
        .serve_with_incoming_shutdown(incoming, stopped(stop));
    tokio::select! {
        served = serving => served.context("serving")?,
        () = grace => {}
    }
    Ok(())
}

/// The credentials of the flags and files.
fn credentials(args: &Args) -> Result<Credentials> {
    let mut clients = args.client_tokens.clone();
    let mut workers = args.worker_tokens.clone();
    if let Some(path) = &args.client_tokens_file {
        clients.extend(read_tokens_file(path).context("--client-tokens-file")?);
    }
    if let Some(path) = &args.worker_tokens_file {
        workers.extend(read_tokens_file(path).context("--worker-tokens-file")?);
    }
    Ok(Credentials::new(&clients, &workers, args.token.as_deref())?)
}

/// How long a stopping server waits for calls in flight (worker sessions included)
/// before it exits anyway.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(2);
