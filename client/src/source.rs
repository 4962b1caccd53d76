//! Where the manager's textures come from: a Relief server over gRPC (with an
//! optional injected round trip, to show latency hiding), or the in-process generator
//! — the same ray tracer on one low-priority thread — when no server answers.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender, unbounded_channel};

use relief_core::hash::ContentHash;
use relief_core::scene::Scene;
use relief_proto::convert::{projection_to_pb, vec3_to_pb};
use relief_proto::pb;
use relief_render::impostor::Faces;
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

use crate::intake::Intake;
use crate::link::{Degraded, Link};
use crate::manager::{Arrival, Command, Config, Failure, Manager, ReadyTexture, TextureRequest};

fn to_pb(request: &TextureRequest, scene: ContentHash, client_id: &str) -> pb::ImpostorRequest {
    pb::ImpostorRequest {
        scene_hash: scene.to_string(),
        object: request.object.clone(),
        eye: Some(vec3_to_pb(request.eye)),
        size: request.size,
        depth_bits: request.depth_bits.bits(),
        urgency: if request.needed_in_ms.is_some() {
            pb::Urgency::Predicted
        } else {
            pb::Urgency::Now
        } as i32,
        needed_in_ms: request.needed_in_ms.unwrap_or(0),
        client_id: client_id.to_string(),
        request_id: request.id,
        progressive: request.needed_in_ms.is_none(),
        projection: projection_to_pb(request.projection).into(),
        serve_within: request.serve_within,
        zstd_planes: true,
        zstd_delta_planes: true,
    }
}

/// What a request to the server is made of besides itself: the link it goes over, the
/// faces its object shows, where its textures are made ready, and the half round trip
/// injected each way.
struct Served<'a> {
    link: &'a Link,
    faces: Faces,
    intake: &'a Intake,
    half: Duration,
}

/// A request still unanswered this long after the eye was predicted to need it (after
/// it was sent, for one needed now) is withdrawn and counted as timed out: the server
/// or its workers are stuck, and the manager, asking again, asks for a nearer eye.
/// (Loaded loopback runs answer within 5 s at p99.)
pub const ANSWER_DEADLINE: Duration = Duration::from_secs(10);

/// Serves `commands` over `link` on the current tokio runtime, the textures made ready
/// through `intake`; `rtt` is added to every exchange (half each way). While the link
/// is degraded (see [`crate::link`]) requests go to the local generator instead.
pub fn spawn_remote(
    link: Arc<Link>,
    scene: Arc<Scene>,
    mut commands: UnboundedReceiver<Command>,
    arrivals: UnboundedSender<Arrival>,
    rtt: Duration,
    intake: Intake,
) {
    let half = rtt / 2;
    let (local_tx, local_rx) = unbounded_channel();
    spawn_local(scene.clone(), local_rx, arrivals.clone());
    let watch = tokio::spawn(link.clone().watch(arrivals.clone(), half));
    tokio::spawn(async move {
        while let Some(command) = commands.recv().await {
            let link = link.clone();
            let scene = scene.clone();
            let arrivals = arrivals.clone();
            let local = local_tx.clone();
            let intake = intake.clone();
            tokio::spawn(async move {
                tokio::time::sleep(half).await;
                match command {
                    Command::Withdraw(ids) => {
                        let _ = link.remote.clone().withdraw(&ids).await;
                        let _ = local.send(Command::Withdraw(ids));
                    }
                    Command::Request(request) => {
                        let faces = scene.object(&request.object).map_or(Faces::Both, Faces::of);
                        let from = Served {
                            link: &link,
                            faces,
                            intake: &intake,
                            half,
                        };
                        serve_request(request, from, &arrivals, &local).await;
                    }
                }
            });
        }
        // The manager is gone: so is the run.
        watch.abort();
    });
}

/// Whether `status` says the server could not be reached (or the connection to it
/// broke), as opposed to an answer from it.
fn unreachable(status: &tonic::Status) -> bool {
    // (A connection that broke surfaces as `UNAVAILABLE`, as `CANCELLED` — but for a
    // withdrawal, the server's answer — or as `UNKNOWN` naming the transport.)
    let broken = ["transport", "connection", "broken pipe", "reset"];
    match status.code() {
        tonic::Code::Unavailable => true,
        tonic::Code::Cancelled => status.message() != relief_proto::WITHDRAWN,
        tonic::Code::Unknown => broken.iter().any(|b| status.message().to_lowercase().contains(b)),
        _ => false,
    }
}

/// The wait a refusal for saturation says the server foresaw, if it is one.
fn saturated_wait(status: &tonic::Status) -> Option<Duration> {
    if status.code() != tonic::Code::ResourceExhausted {
        return None;
    }
    let ms: u64 = status
        .metadata()
        .get(relief_proto::SATURATED_METADATA)?
        .to_str()
        .ok()?
        .parse()
        .ok()?;
    Some(Duration::from_millis(ms))
}

/// Asks the server for `request` and passes on what comes back (each result `half`
/// late) — ending, whatever happens, in the final texture or a failure the manager
/// hears of. A scene the server no longer holds is uploaded again and the request
/// asked again, once; a server that cannot be reached, or stops answering mid-way,
/// hands the request to the local generator.
async fn serve_request(
    request: TextureRequest,
    Served {
        link,
        faces,
        intake,
        half,
    }: Served<'_>,
    arrivals: &UnboundedSender<Arrival>,
    local: &UnboundedSender<Command>,
) {
    let id = request.id;
    let fail = |failure: Failure| {
        let _ = arrivals.send(Arrival::Failed { id, failure });
    };
    let to_local = |request: TextureRequest| {
        let _ = local.send(Command::Request(request));
    };
    if link.health.degraded().is_some() {
        return to_local(request);
    }
    let wire = to_pb(&request, link.scene_hash, &link.remote.client_id);
    let mut remote = link.remote.clone();
    let sent = tokio::time::Instant::now();
    let mut stream = None;
    for first_try in [true, false] {
        let uploads = link.uploads_done().await;
        match remote.request(wire.clone()).await {
            Ok(s) => {
                link.heard();
                stream = Some(s);
                break;
            }
            // (The manager gone, the run is over: a server stopping with it is no news.)
            Err(_) if arrivals.is_closed() => return,
            Err(e) if unreachable(&e) => {
                link.health
                    .degrade(Degraded::Unreachable(e.message().to_string()));
                return to_local(request);
            }
            // A prediction the saturated server will not make in time.
            Err(e) if let Some(wait) = saturated_wait(&e) => return fail(Failure::Shed(wait)),
            // The server has lost the scene (restarted, or evicted it): upload it again.
            Err(e) if e.code() == tonic::Code::NotFound && first_try => {
                if let Err(upload) = link.upload_again(uploads).await {
                    return fail(Failure::Refused(upload.to_string()));
                }
            }
            Err(e) => return fail(Failure::Refused(e.message().to_string())),
        }
    }
    let Some(mut stream) = stream else {
        return fail(Failure::Refused(
            "the scene was uploaded again, and is still not known".into(),
        ));
    };
    let deadline = sent + Duration::from_millis(request.needed_in_ms.unwrap_or(0)) + ANSWER_DEADLINE;
    let mut finished = false;
    loop {
        let Ok(message) = tokio::time::timeout_at(deadline, stream.message()).await else {
            let _ = remote.withdraw(&[id]).await;
            return fail(Failure::TimedOut(deadline - sent));
        };
        match message {
            Ok(Some(result)) => {
                link.heard();
                let is_final = result.r#final;
                finished |= is_final;
                tokio::time::sleep(half).await;
                let Some(texture) = result.texture else {
                    fail(Failure::Refused("a result without a texture".into()));
                    continue;
                };
                // Decoding and making ready take milliseconds of CPU a texture: off the
                // runtime's threads, whose timers (the link's looks among them) they
                // held up — with many clients in one process, long enough for a busy
                // server to look lost.
                let (arrived, intake) = (Instant::now(), intake.clone());
                let ready = tokio::task::spawn_blocking(move || {
                    intake.ready("texture", &texture, faces, arrived).map(Box::new)
                })
                .await;
                match ready {
                    Ok(Ok(texture)) => {
                        let _ = arrivals.send(Arrival::Texture {
                            id,
                            texture,
                            is_final,
                        });
                    }
                    Ok(Err(e)) => fail(Failure::Refused(e.message().to_string())),
                    // (Only a panic while decoding, or a runtime shutting down.)
                    Err(e) => fail(Failure::Refused(format!("making the texture ready: {e}"))),
                }
            }
            // After the final texture nothing more is owed. Before it, the end is a
            // failure: the manager must hear of a stream cut off (and ignores the end
            // of one it withdrew).
            Ok(None) | Err(_) if finished => return,
            Ok(None) => {
                return fail(Failure::Refused(
                    "the result stream ended without a final texture".into(),
                ));
            }
            // (The manager gone, the run is over: a server stopping with it is no news.)
            Err(_) if arrivals.is_closed() => return,
            Err(e) if unreachable(&e) => {
                link.health
                    .degrade(Degraded::Unreachable(e.message().to_string()));
                return to_local(request);
            }
            // A prediction the saturated server gave up on before starting it.
            Err(e) if let Some(wait) = saturated_wait(&e) => return fail(Failure::Shed(wait)),
            Err(e) => return fail(Failure::Refused(e.message().to_string())),
        }
    }
}

/// Serves `commands` in-process on one low-priority thread: needed-now requests first,
/// withdrawn ones dropped.
pub fn spawn_local(
    scene: Arc<Scene>,
    mut commands: UnboundedReceiver<Command>,
    arrivals: UnboundedSender<Arrival>,
) {
    std::thread::Builder::new()
        .name("relief-local-generator".into())
        .spawn(move || {
            let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(1).build() else {
                return;
            };
            // By mesh: placements of one mesh bake alike (in the object's frame).
            let mut tracers: HashMap<relief_core::hash::ContentHash, ObjectTracer> = HashMap::new();
            let mut queue: VecDeque<TextureRequest> = VecDeque::new();
            loop {
                // Take everything that has come in; wait only when idle.
                let next = if queue.is_empty() {
                    commands.blocking_recv()
                } else {
                    commands.try_recv().ok()
                };
                match next {
                    Some(Command::Request(r)) => {
                        // Needed-now requests before predicted ones, each kind in the
                        // order asked (newest-first would starve an old one).
                        let at = match r.needed_in_ms {
                            None => queue
                                .iter()
                                .position(|q| q.needed_in_ms.is_some())
                                .unwrap_or(queue.len()),
                            Some(_) => queue.len(),
                        };
                        queue.insert(at, r);
                        continue;
                    }
                    Some(Command::Withdraw(ids)) => {
                        queue.retain(|r| !ids.contains(&r.id));
                        continue;
                    }
                    None if queue.is_empty() => return,
                    None => {}
                }
                let Some(request) = queue.pop_front() else {
                    continue;
                };
                let arrival = match scene.object(&request.object) {
                    Err(e) => Arrival::Failed {
                        id: request.id,
                        failure: Failure::Refused(e.to_string()),
                    },
                    Ok(object) => {
                        let tracer = tracers
                            .entry(object.hash)
                            .or_insert_with(|| pool.install(|| ObjectTracer::new(object)));
                        match pool.install(|| {
                            bake(
                                tracer,
                                request.eye,
                                request.size,
                                request.depth_bits,
                                request.projection,
                            )
                        }) {
                            Ok(texture) => Arrival::Texture {
                                id: request.id,
                                texture: Box::new(ReadyTexture::new(texture, Faces::of(object))),
                                is_final: true,
                            },
                            Err(e) => Arrival::Failed {
                                id: request.id,
                                failure: Failure::Refused(e.to_string()),
                            },
                        }
                    }
                };
                if arrivals.send(arrival).is_err() {
                    return;
                }
            }
        })
        .map(drop)
        .unwrap_or_else(|e| tracing::warn!("no local generator: {e}"));
}

/// A manager of `scene` whose textures come over `link` (its requests served on the
/// current tokio runtime; `rtt` added to every exchange, half each way), made ready
/// through `intake` — shared by the clients of a process, its own for a client alone.
/// The link's [`Health`](crate::link::Health) says how long the run was degraded.
pub fn remote_manager(
    scene: &Arc<Scene>,
    config: Config,
    link: Arc<Link>,
    rtt: Duration,
    intake: Intake,
) -> Manager {
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    spawn_remote(link, scene.clone(), commands_rx, arrivals_tx, rtt, intake);
    Manager::new(scene, config, commands_tx, arrivals_rx)
}

/// A manager of `scene` whose textures the in-process generator makes.
pub fn local_manager(scene: &Arc<Scene>, config: Config) -> Manager {
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    spawn_local(scene.clone(), commands_rx, arrivals_tx);
    Manager::new(scene, config, commands_tx, arrivals_rx)
}
