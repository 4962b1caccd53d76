//! The worker's life: connect, register, take jobs, bake, send results; reconnect with
//! backoff when the server goes away; drain and stop on SIGINT/SIGTERM.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow};
use rayon::prelude::*;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;
use tokio_stream::wrappers::UnboundedReceiverStream;
use tonic::codec::CompressionEncoding;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Channel, Endpoint};
use tracing::Instrument;

use relief_core::hash::ContentHash;
use relief_core::scene::{Scene, SceneLimits};
use relief_proto::auth::BearerToken;
use relief_proto::bundle::Bundle;
use relief_proto::convert::{
    depth_bits_from_pb, hash_from_pb, projection_from_pb, size_from_pb, texture_to_pb, vec3_from_pb,
};
use relief_proto::limits::{MAX_SCENE_FETCH_MESSAGE_BYTES, MAX_TEXTURE_MESSAGE_BYTES};
use relief_proto::pb;
use relief_proto::planes::compressed;
use relief_trace::bake::bake_unless_cancelled;
use relief_trace::tracer::ObjectTracer;

use crate::Args;
use crate::metrics::WorkerMetrics;

type Scenes = pb::scenes_client::ScenesClient<InterceptedService<Channel, BearerToken>>;

/// The first redial after a lost session waits this long, …
const REDIAL_FIRST: Duration = Duration::from_millis(100);
/// … each next one twice as long, up to this: a server back after a restart is found
/// within seconds, and a dead one is not dialled in a loop.
const REDIAL_MAX: Duration = Duration::from_secs(5);
/// A session that lasted this long was a good one: the next redial starts again from
/// [`REDIAL_FIRST`].
const REDIAL_RESET_AFTER: Duration = Duration::from_secs(10);

/// A draining worker waits at most this long for the server to read its last results.
const DRAIN_WAIT: Duration = Duration::from_secs(10);

/// A progressive job (one needed now) gets a preview first, this many times smaller in
/// edge (a sixteenth of the texels: there in a fraction of the time) …
const PREVIEW_DIVISOR: u32 = 4;
/// … when the texture is at least this big (below, the final texture is as quick).
const PREVIEW_MIN_EDGE: u32 = 64;

/// A scene this worker has loaded: every object's tracer, built when the scene is
/// loaded (a BVH built on a job's demand — a million triangles: a second on a busy
/// host — delayed that job and all queued behind it, late in a flight when latency
/// matters). The tracers own the objects; the scene itself is not kept.
struct Loaded {
    /// The scene's name and its objects' ([`Scene::object_names`]), for errors.
    name: String,
    names: String,
    tracers: HashMap<String, Arc<ObjectTracer>>,
}

impl Loaded {
    /// Builds every object's tracer, in parallel: each mesh's BVH once, shared by its
    /// placements; and counts each mesh's edges, which a bake asks for (whether it may
    /// look past its rims: `relief_trace::hidden`), so that no job pays for it.
    fn new(scene: Scene) -> Loaded {
        let names = scene.object_names();
        let tracers: HashMap<String, Arc<ObjectTracer>> = ObjectTracer::all(scene.objects)
            .into_iter()
            .map(|t| (t.object.name.clone(), Arc::new(t)))
            .collect();
        // (A mesh's census is shared by its placements: the first to ask counts.)
        tracers.par_iter().for_each(|(_, t)| {
            t.object.edge_census();
        });
        Loaded {
            name: scene.name,
            names,
            tracers,
        }
    }

    /// The tracer of `object`, or the scene's own error naming what it holds.
    fn tracer(&self, object: &str) -> Result<Arc<ObjectTracer>, relief_core::Error> {
        self.tracers
            .get(object)
            .cloned()
            .ok_or_else(|| relief_core::Error::UnknownObject {
                scene: self.name.clone(),
                name: object.to_string(),
                available: self.names.clone(),
            })
    }
}

/// The scenes of this worker by hash, each loaded once: a slot is taken under the map's
/// lock, the loading done in the slot (other scenes' jobs go on meanwhile, the same
/// scene's wait for it). A failed load leaves the slot empty for the next job to retry.
type LoadedScenes = Arc<Mutex<HashMap<ContentHash, Arc<tokio::sync::OnceCell<Arc<Loaded>>>>>>;

/// What every job of a session shares.
#[derive(Clone)]
struct JobContext {
    scenes: Scenes,
    loaded: LoadedScenes,
    scene_dir: PathBuf,
    /// Each running job's cancel flag, set when the server cancels it.
    cancelled: Arc<Mutex<HashMap<u64, Arc<AtomicBool>>>>,
    out: mpsc::UnboundedSender<pb::WorkerMessage>,
    metrics: WorkerMetrics,
}

impl JobContext {
    /// The server cancelled job `id`: its bake stops (if it is still running here).
    fn cancel(&self, id: u64) {
        if let Some(flag) = lock(&self.cancelled).get(&id) {
            flag.store(true, Ordering::Relaxed);
        }
    }
}

enum End {
    /// Asked to stop, and every held job is finished.
    Stopped,
    /// The connection was lost (or never made).
    Lost(anyhow::Error),
    /// The server refused the worker (wrong token): retrying would not help.
    Refused(anyhow::Error),
}

pub async fn run(args: Args) -> Result<()> {
    relief_proto::connect::refuse_token_in_clear(&args.server, args.token.as_deref(), args.allow_insecure)
        .map_err(|e| anyhow!("--server/--token: {e}"))?;
    let endpoint = relief_proto::connect::endpoint(&args.server, args.tls_ca.as_deref())
        .map_err(|e| anyhow!("--server/--tls-ca: {e}"))?;
    let auth = BearerToken::new(args.token.as_deref()).map_err(|e| anyhow!("--token: {e}"))?;
    // (Held to the end of `run`: a directory of its own is removed then.)
    let scenes = relief_proto::bundle::SceneDir::new(args.scene_dir.clone(), "relief-worker")?;
    let scene_dir = scenes.path();
    // A scene directory it cannot write would fail every job: refuse to start.
    std::fs::create_dir_all(scene_dir)
        .and_then(|()| relief_core::scratch::probe_writable(scene_dir))
        .map_err(|e| anyhow!("--scene-dir {}: {e}", scene_dir.display()))?;
    let name = args.name.clone().unwrap_or_else(|| {
        let host = std::fs::read_to_string("/etc/hostname").unwrap_or_default();
        format!("{}-{}", host.trim(), std::process::id())
    });
    let stop = relief_proto::shutdown::watch();
    let loaded = LoadedScenes::default();
    let (metrics, registry) = WorkerMetrics::new();
    if let Some(address) = args.metrics_listen {
        let listener = tokio::net::TcpListener::bind(address)
            .await
            .map_err(|e| anyhow!("--metrics-listen: binding {address}: {e}"))?;
        tracing::info!("metrics on http://{address}/metrics");
        tokio::spawn(relief_proto::metrics::serve(listener, Arc::new(registry)));
    }
    let mut backoff = REDIAL_FIRST;
    loop {
        if *stop.borrow() {
            return Ok(());
        }
        let started = Instant::now();
        match session(
            &args,
            &name,
            &endpoint,
            &auth,
            scene_dir,
            loaded.clone(),
            metrics.clone(),
            stop.clone(),
        )
        .await
        {
            End::Stopped => return Ok(()),
            // Retrying cannot mend a refused token.
            End::Refused(e) => return Err(e),
            End::Lost(e) => {
                if started.elapsed() > REDIAL_RESET_AFTER {
                    backoff = REDIAL_FIRST;
                }
                tracing::warn!(
                    "session with {} ended: {e:#}; retrying in {backoff:?}",
                    args.server
                );
                let mut stop = stop.clone();
                tokio::select! {
                    _ = tokio::time::sleep(backoff) => {}
                    _ = stop.changed() => return Ok(()),
                }
                backoff = (backoff * 2).min(REDIAL_MAX);
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
async fn session(
    args: &Args,
    name: &str,
    endpoint: &Endpoint,
    auth: &BearerToken,
    scene_dir: &std::path::Path,
    loaded: LoadedScenes,
    metrics: WorkerMetrics,
    mut stop: watch::Receiver<bool>,
) -> End {
    let channel = match endpoint.connect().await {
        Ok(c) => c,
        Err(e) => return End::Lost(anyhow!("connecting: {}", relief_proto::connect::explain(&e))),
    };
    // (Results carry their planes compressed already: sent plain.)
    let mut workers = pb::workers_client::WorkersClient::with_interceptor(channel.clone(), auth.clone())
        .accept_compressed(CompressionEncoding::Zstd)
        .max_encoding_message_size(MAX_TEXTURE_MESSAGE_BYTES);
    let scenes = pb::scenes_client::ScenesClient::with_interceptor(channel, auth.clone())
        .send_compressed(CompressionEncoding::Zstd)
        .accept_compressed(CompressionEncoding::Zstd)
        .max_decoding_message_size(MAX_SCENE_FETCH_MESSAGE_BYTES);
    let (out, outbound) = mpsc::unbounded_channel();
    let _ = out.send(pb::WorkerMessage {
        kind: Some(pb::worker_message::Kind::Register(pb::Register {
            name: name.to_string(),
            slots: args.slots,
            threads: rayon::current_num_threads() as u32,
        })),
    });
    let mut inbound = match workers.session(UnboundedReceiverStream::new(outbound)).await {
        Ok(r) => r.into_inner(),
        Err(e) if e.code() == tonic::Code::Unauthenticated || e.code() == tonic::Code::PermissionDenied => {
            return End::Refused(anyhow!(
                "the server refused this worker: {} (check --token)",
                e.message()
            ));
        }
        // (A registration the server finds invalid would be refused again.)
        Err(e) if e.code() == tonic::Code::InvalidArgument => {
            return End::Refused(anyhow!("the server refused this worker: {}", e.message()));
        }
        Err(e) => return End::Lost(anyhow!("opening the session: {}", e.message())),
    };
    tracing::info!("registered with {} as {name}", args.server);
    metrics.registered.set(1);
    let heartbeat = {
        let out = out.clone();
        let period = Duration::from_millis(args.heartbeat_ms);
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(period);
            loop {
                tick.tick().await;
                let beat = pb::WorkerMessage {
                    kind: Some(pb::worker_message::Kind::Heartbeat(pb::Heartbeat {})),
                };
                if out.send(beat).is_err() {
                    return;
                }
            }
        })
    };
    let context = JobContext {
        scenes,
        loaded,
        scene_dir: scene_dir.to_path_buf(),
        cancelled: Arc::new(Mutex::new(HashMap::new())),
        out,
        metrics: metrics.clone(),
    };
    let mut jobs = JoinSet::new();
    let end = loop {
        tokio::select! {
            message = inbound.message() => match message {
                Ok(Some(m)) => match m.kind {
                    Some(pb::server_message::Kind::Job(job)) => {
                        // (Registered before the job runs: a cancel may follow at once.)
                        let cancelled = Arc::new(AtomicBool::new(false));
                        lock(&context.cancelled).insert(job.job_id, cancelled.clone());
                        jobs.spawn(run_job(job, context.clone(), cancelled));
                    }
                    Some(pb::server_message::Kind::Cancel(c)) => context.cancel(c.job_id),
                    None => {}
                },
                Ok(None) => break End::Lost(anyhow!("the server closed the session")),
                Err(e) => break End::Lost(anyhow!("{}", e.message())),
            },
            Some(_) = jobs.join_next(), if !jobs.is_empty() => {}
            _ = stop.changed() => {
                // Drain: say so (the server hands out no more), finish (and send) what
                // we hold — but still listen, so a job cancelled meanwhile stops. (One
                // already on its way is left: the server gives it to another when the
                // session ends.)
                tracing::info!("stopping: finishing {} job(s)", jobs.len());
                let _ = context.out.send(pb::WorkerMessage {
                    kind: Some(pb::worker_message::Kind::Draining(pb::Draining {})),
                });
                while !jobs.is_empty() {
                    tokio::select! {
                        _ = jobs.join_next() => {}
                        message = inbound.message() => match message {
                            Ok(Some(pb::ServerMessage {
                                kind: Some(pb::server_message::Kind::Cancel(c)),
                            })) => context.cancel(c.job_id),
                            Ok(Some(_)) => {}
                            // (The server is gone: finish without listening.)
                            Ok(None) | Err(_) => while jobs.join_next().await.is_some() {},
                        },
                    }
                }
                break End::Stopped;
            }
        }
    };
    heartbeat.abort();
    metrics.registered.set(0);
    if matches!(end, End::Stopped) {
        // The results are queued, not yet sent: close this side (every sender gone)
        // and wait — bounded — for the server to end the session, which it does once
        // it has read them all. (Exiting at once lost the last result with the
        // process; jobs the server handed out meanwhile it gives to others.)
        let _ = heartbeat.await;
        drop(context);
        let _ = tokio::time::timeout(DRAIN_WAIT, async {
            while let Ok(Some(_)) = inbound.message().await {}
        })
        .await;
    }
    end
}

/// Bakes one job and sends its result (a preview first when asked), its failure, or —
/// `cancelled` set before it finished — that it stopped.
async fn run_job(job: pb::Job, context: JobContext, cancelled: Arc<AtomicBool>) {
    let id = job.job_id;
    let out = context.out.clone();
    // (Every log line of the job names it.)
    let span = tracing::info_span!("job", id, object = %job.object, size = job.size);
    context.metrics.jobs_running.inc();
    let baked = bake_job(job, &context, &cancelled).instrument(span).await;
    context.metrics.jobs_running.dec();
    let kind = match baked {
        Ok(Baked::Finished) => None,
        Ok(Baked::Stopped) => Some(pb::worker_message::Kind::Stopped(pb::JobStopped { job_id: id })),
        Err(reason) => {
            context.metrics.bake_ended("failed");
            Some(pb::worker_message::Kind::Failed(pb::JobFailed {
                job_id: id,
                reason,
            }))
        }
    };
    if let Some(kind) = kind {
        let _ = out.send(pb::WorkerMessage { kind: Some(kind) });
    }
    lock(&context.cancelled).remove(&id);
}

/// How a job's bakes ended.
enum Baked {
    /// Every texture was sent.
    Finished,
    /// Cancelled before the last was.
    Stopped,
}

async fn bake_job(job: pb::Job, context: &JobContext, cancelled: &Arc<AtomicBool>) -> Result<Baked, String> {
    let message = |e: tonic::Status| e.message().to_string();
    let hash = hash_from_pb("scene_hash", &job.scene_hash).map_err(message)?;
    let eye = vec3_from_pb("eye", job.eye.as_ref()).map_err(message)?;
    let size = size_from_pb("size", job.size).map_err(message)?;
    let bits = depth_bits_from_pb("depth_bits", job.depth_bits).map_err(message)?;
    let projection = projection_from_pb("projection", job.projection).map_err(message)?;
    let loaded = scene(hash, context).await?;
    let tracer = loaded.tracer(&job.object).map_err(|e| e.to_string())?;
    let mut sizes = vec![size];
    if job.progressive && size >= PREVIEW_MIN_EDGE {
        sizes.insert(0, size / PREVIEW_DIVISOR);
    }
    for (k, edge) in sizes.iter().copied().enumerate() {
        if cancelled.load(Ordering::Relaxed) {
            return Ok(Baked::Stopped);
        }
        let (tracer, flag) = (tracer.clone(), cancelled.clone());
        let start = Instant::now();
        // (Compressed here, once: see `relief_proto::planes`.)
        let texture = tokio::task::spawn_blocking(move || {
            bake_unless_cancelled(&tracer, eye, edge, bits, projection, &flag)
                .map(|baked| baked.map(|texture| compressed(texture_to_pb(&texture))))
        })
        .await
        .map_err(|e| e.to_string())?
        .map_err(|e| e.to_string())?;
        let Some(texture) = texture else {
            tracing::debug!(edge, "cancelled: stopped mid-bake");
            context.metrics.bake_ended("stopped");
            return Ok(Baked::Stopped);
        };
        tracing::debug!(edge, ms = start.elapsed().as_millis() as u64, "baked");
        let metrics = &context.metrics;
        metrics.bake_ended("finished");
        metrics.bake_seconds.observe(start.elapsed().as_secs_f64());
        metrics.rays.inc_by(u64::from(edge) * u64::from(edge));
        let result = pb::JobResult {
            job_id: job.job_id,
            texture: Some(texture),
            r#final: k + 1 == sizes.len(),
            bake_ms: start.elapsed().as_millis() as u32,
        };
        let _ = context.out.send(pb::WorkerMessage {
            kind: Some(pb::worker_message::Kind::Result(result)),
        });
    }
    Ok(Baked::Finished)
}

/// The scene `hash`, fetched from the server and loaded the first time.
async fn scene(hash: ContentHash, context: &JobContext) -> Result<Arc<Loaded>, String> {
    let slot = lock(&context.loaded).entry(hash).or_default().clone();
    slot.get_or_try_init(|| fetch_and_load(hash, context))
        .await
        .cloned()
}

/// Fetches scene `hash` from the server, unpacks and loads it, and builds its tracers.
async fn fetch_and_load(hash: ContentHash, context: &JobContext) -> Result<Arc<Loaded>, String> {
    let mut scenes = context.scenes.clone();
    let mut stream = scenes
        .get_scene(pb::SceneRef {
            hash: hash.to_string(),
        })
        .await
        .map_err(|e| format!("fetching scene {hash}: {}", e.message()))?
        .into_inner();
    let mut encoded = Vec::new();
    while let Some(chunk) = stream
        .message()
        .await
        .map_err(|e| format!("fetching scene {hash}: {}", e.message()))?
    {
        encoded.extend_from_slice(&chunk.data);
    }
    let bundle = Bundle::decode(encoded).map_err(|e| e.to_string())?;
    let dir = context.scene_dir.clone();
    let loaded =
        tokio::task::spawn_blocking(move || bundle.load(&dir, &SceneLimits::default()).map(Loaded::new))
            .await
            .map_err(|e| e.to_string())?
            .map_err(|e| format!("loading scene {hash}: {e}"))?;
    Ok(Arc::new(loaded))
}

/// Locks `mutex`, taking over its data if a job panicked while holding it (the sets it
/// guards stay valid whatever a job did).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|p| p.into_inner())
}
