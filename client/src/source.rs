//! Where the manager's textures come from: a Relief server over gRPC (with an
//! optional injected round trip, to show latency hiding), or the in-process generator
//! — the same ray tracer on one low-priority thread — when no server answers.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender, unbounded_channel};

use relief_core::hash::ContentHash;
use relief_core::scene::Scene;
use relief_proto::convert::{texture_from_pb, vec3_to_pb};
use relief_proto::pb;
use relief_render::impostor::Faces;
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

use crate::manager::{Arrival, Command, Config, Manager, ReadyTexture, TextureRequest};
use crate::remote::Remote;

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
    }
}

/// What a request to the server is made of besides itself: the scene's hash there, the
/// faces its object shows, and the half round trip injected each way.
#[derive(Clone, Copy)]
struct Served {
    scene_hash: ContentHash,
    faces: Faces,
    half: Duration,
}

/// Serves `commands` with `remote` on the current tokio runtime; `rtt` is added to
/// every exchange (half each way). A request the server cannot take (unreachable)
/// goes to the local generator instead.
pub fn spawn_remote(
    remote: Remote,
    scene_hash: ContentHash,
    scene: Arc<Scene>,
    mut commands: UnboundedReceiver<Command>,
    arrivals: UnboundedSender<Arrival>,
    rtt: Duration,
) {
    let half = rtt / 2;
    let (local_tx, local_rx) = unbounded_channel();
    spawn_local(scene.clone(), local_rx, arrivals.clone());
    tokio::spawn(async move {
        while let Some(command) = commands.recv().await {
            let mut remote = remote.clone();
            let scene = scene.clone();
            let arrivals = arrivals.clone();
            let local = local_tx.clone();
            tokio::spawn(async move {
                tokio::time::sleep(half).await;
                match command {
                    Command::Withdraw(ids) => {
                        let _ = remote.withdraw(&ids).await;
                        let _ = local.send(Command::Withdraw(ids));
                    }
                    Command::Request(request) => {
                        let faces = scene.object(&request.object).map_or(Faces::Both, Faces::of);
                        let from = Served {
                            scene_hash,
                            faces,
                            half,
                        };
                        serve_request(&mut remote, request, from, &arrivals, &local).await;
                    }
                }
            });
        }
    });
}

/// Asks `remote` for `request` and passes on what comes back (each result `half` late)
/// — ending, whatever happens, in the final texture or a failure the manager hears of.
/// A server that cannot be reached hands the request to the local generator.
async fn serve_request(
    remote: &mut Remote,
    request: TextureRequest,
    Served {
        scene_hash,
        faces,
        half,
    }: Served,
    arrivals: &UnboundedSender<Arrival>,
    local: &UnboundedSender<Command>,
) {
    let id = request.id;
    let fail = |reason: String| {
        let _ = arrivals.send(Arrival::Failed { id, reason });
    };
    let wire = to_pb(&request, scene_hash, &remote.client_id);
    let mut stream = match remote.request(wire).await {
        Ok(s) => s,
        Err(e) if e.code() == tonic::Code::Unavailable => {
            let _ = local.send(Command::Request(request));
            return;
        }
        Err(e) => return fail(e.message().to_string()),
    };
    let mut finished = false;
    loop {
        match stream.message().await {
            Ok(Some(result)) => {
                finished |= result.r#final;
                tokio::time::sleep(half).await;
                match result.texture.as_ref().map(|t| texture_from_pb("texture", t)) {
                    Some(Ok(texture)) => {
                        let _ = arrivals.send(Arrival::Texture {
                            id,
                            texture: Box::new(ReadyTexture::new(texture, faces)),
                            is_final: result.r#final,
                        });
                    }
                    Some(Err(e)) => fail(e.message().to_string()),
                    None => fail("a result without a texture".into()),
                }
            }
            // After the final texture nothing more is owed. Before it, the end is a
            // failure: the manager must hear of a stream cut off (and ignores the end
            // of one it withdrew).
            Ok(None) | Err(_) if finished => return,
            Ok(None) => return fail("the result stream ended without a final texture".into()),
            Err(e) => return fail(e.message().to_string()),
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
            let mut tracers: HashMap<String, ObjectTracer> = HashMap::new();
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
                        reason: e.to_string(),
                    },
                    Ok(object) => {
                        let tracer = tracers
                            .entry(request.object.clone())
                            .or_insert_with(|| pool.install(|| ObjectTracer::new(object)));
                        match pool.install(|| bake(tracer, request.eye, request.size, request.depth_bits)) {
                            Ok(texture) => Arrival::Texture {
                                id: request.id,
                                texture: Box::new(ReadyTexture::new(texture, Faces::of(object))),
                                is_final: true,
                            },
                            Err(e) => Arrival::Failed {
                                id: request.id,
                                reason: e.to_string(),
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

/// A manager of `scene` whose textures come from `remote`, the scene uploaded there as
/// `scene_hash` (its requests served on the current tokio runtime; `rtt` added to
/// every exchange, half each way).
pub fn remote_manager(
    scene: &Arc<Scene>,
    config: Config,
    remote: Remote,
    scene_hash: ContentHash,
    rtt: Duration,
) -> Manager {
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    spawn_remote(remote, scene_hash, scene.clone(), commands_rx, arrivals_tx, rtt);
    Manager::new(scene, config, commands_tx, arrivals_rx)
}

/// A manager of `scene` whose textures the in-process generator makes.
pub fn local_manager(scene: &Arc<Scene>, config: Config) -> Manager {
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    spawn_local(scene.clone(), commands_rx, arrivals_tx);
    Manager::new(scene, config, commands_tx, arrivals_rx)
}
