//! The gRPC services over [`State`]: `Scenes`, `Impostors` and `Workers`.

use std::path::PathBuf;
use std::pin::Pin;
use std::sync::{Arc, Mutex, MutexGuard};

use tokio::sync::mpsc::unbounded_channel;
use tokio_stream::Stream;
use tokio_stream::wrappers::UnboundedReceiverStream;
use tonic::{Request, Response, Status, Streaming};

use relief_core::scene::SceneLimits;
use relief_proto::bundle::Bundle;
use relief_proto::convert::{
    check_client_id, check_register, check_texture_pb, hash_from_pb, request_from_pb,
};
use relief_proto::limits::SCENE_CHUNK_BYTES;
use relief_proto::pb;

use crate::identity::{Caller, Role};
use crate::state::{Admission, State, StoredObject, StoredScene};

/// The server: its state under one lock, and where received scenes are unpacked.
pub struct Shared {
    state: Mutex<State>,
    scene_dir: PathBuf,
    /// What an uploaded scene may cost, checked before it is built.
    scene_limits: SceneLimits,
    uploads: Uploads,
}

impl Shared {
    pub fn new(state: State, scene_dir: PathBuf, scene_limits: SceneLimits, uploads: Uploads) -> Arc<Shared> {
        Arc::new(Shared {
            state: Mutex::new(state),
            scene_dir,
            scene_limits,
            uploads,
        })
    }

    /// The state, even if a panicking thread poisoned the lock (every method leaves it
    /// consistent between statements that matter).
    pub fn state(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// All three services share one [`Shared`].
#[derive(Clone)]
pub struct Service(pub Arc<Shared>);

/// A reply of a few bytes: compressing it would cost more than it saves.
fn small<T>(message: T) -> Response<T> {
    let mut response = Response::new(message);
    response.disable_compression();
    response
}

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// One request's results. Dropped before the request ended — the client cancelled the
/// call or went away — it withdraws the request, which stops its job (on the worker
/// too) when nobody else waits for it: no texture is baked for nobody.
pub struct ResultStream {
    results: UnboundedReceiverStream<Result<pb::ImpostorResult, Status>>,
    /// The state's sender for this stream, while the request waits (it is dropped
    /// when the request ends, so this stream does not keep itself open).
    sender: tokio::sync::mpsc::WeakUnboundedSender<Result<pb::ImpostorResult, Status>>,
    shared: Arc<Shared>,
    client_id: String,
    request_id: u64,
    /// The compressed planes the client reads (see `relief_proto::planes`); for one
    /// that does not read a texture's, its planes are decompressed here, on its own
    /// stream, not where the state is held.
    reads_planes: relief_proto::planes::ReadsPlanes,
}

impl Stream for ResultStream {
    type Item = Result<pb::ImpostorResult, Status>;

    fn poll_next(
        mut self: Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Self::Item>> {
        let reads_planes = self.reads_planes;
        Pin::new(&mut self.results).poll_next(cx).map(|item| {
            item.map(|result| {
                result.and_then(|r| match r.texture {
                    Some(texture) if !reads_planes.reads(texture.encoding) => {
                        // (Checked as it arrived: this fails only on the server's own
                        // mistake.)
                        let raw = relief_proto::planes::raw("texture", &texture)
                            .map_err(|e| Status::internal(e.message().to_string()))?;
                        Ok(pb::ImpostorResult {
                            texture: Some(raw),
                            ..r
                        })
                    }
                    _ => Ok(r),
                })
            })
        })
    }
}

impl Drop for ResultStream {
    fn drop(&mut self) {
        // After the final result (or an answer from the cache) nothing holds the
        // sender any more: nothing to withdraw.
        let Some(results) = self.sender.upgrade() else {
            return;
        };
        let mut state = self.shared.state();
        if state.withdraw_own(&self.client_id, self.request_id, &results) {
            tracing::debug!(client = %self.client_id, id = self.request_id, "the client went away: withdrawn");
            state.dispatch();
        }
    }
}

/// How uploads are bounded: bytes (decompressed) of one, time, and how many at once.
pub struct Uploads {
    pub max_bytes: usize,
    pub timeout: std::time::Duration,
    pub at_once: usize,
    slots: tokio::sync::Semaphore,
}

impl Uploads {
    pub fn new(max_bytes: usize, timeout: std::time::Duration, at_once: usize) -> Uploads {
        Uploads {
            max_bytes,
            timeout,
            at_once,
            slots: tokio::sync::Semaphore::new(at_once),
        }
    }
}

/// An upload's chunks, joined: an error as soon as they pass `max_bytes` (counted as
/// decoded, after decompression — a few compressed bytes can be a great many).
async fn receive(mut chunks: Streaming<pb::SceneChunk>, max_bytes: usize) -> Result<Vec<u8>, Status> {
    let mut encoded = Vec::new();
    while let Some(chunk) = chunks.message().await? {
        if encoded.len() + chunk.data.len() > max_bytes {
            return Err(Status::resource_exhausted(format!(
                "field `data`: the scene exceeds {max_bytes} bytes (the server's --max-upload-mb)"
            )));
        }
        encoded.extend_from_slice(&chunk.data);
    }
    Ok(encoded)
}

/// Removes scenes' unpacked files, off the async threads; a failure is logged (the
/// directory is the server's own, removed whole when it exits).
fn remove_scene_files(dirs: Vec<PathBuf>) {
    if dirs.is_empty() {
        return;
    }
    tokio::task::spawn_blocking(move || dirs.iter().for_each(|dir| remove_dir(dir)));
}

/// Removes one scene's unpacked files (none there is no error).
fn remove_dir(dir: &std::path::Path) {
    if let Err(e) = std::fs::remove_dir_all(dir)
        && e.kind() != std::io::ErrorKind::NotFound
    {
        tracing::warn!(dir = %dir.display(), "removing a scene's files: {e}");
    }
}

/// A client's id as the state keys it: under its credential's name, so that ids chosen
/// by two credentials never meet.
fn scoped(caller: &Caller, client_id: &str) -> String {
    format!("{}/{client_id}", caller.name)
}

#[tonic::async_trait]
impl pb::scenes_server::Scenes for Service {
    async fn put_scene(
        &self,
        request: Request<Streaming<pb::SceneChunk>>,
    ) -> Result<Response<pb::SceneRef>, Status> {
        let caller = Caller::of(&request)?;
        caller.require(Role::Client)?;
        let uploads = &self.0.uploads;
        // (Each upload holds up to its bytes in memory: so many at once, no more.)
        let _slot = uploads.slots.try_acquire().map_err(|_| {
            Status::resource_exhausted(format!(
                "{} uploads are already in progress (the server's --max-uploads)",
                uploads.at_once
            ))
        })?;
        let encoded = tokio::time::timeout(uploads.timeout, receive(request.into_inner(), uploads.max_bytes))
            .await
            .map_err(|_| {
                Status::deadline_exceeded(format!(
                    "the upload took longer than {} ms (the server's --upload-timeout-ms)",
                    uploads.timeout.as_millis()
                ))
            })??;
        let bundle =
            Bundle::decode(encoded).map_err(|e| Status::invalid_argument(format!("field `data`: {e}")))?;
        let hash = bundle.hash;
        if self.0.state().has_scene(&hash) {
            self.0.state().add_owner(hash, &caller.name);
            return Ok(Response::new(pb::SceneRef {
                hash: hash.to_string(),
            }));
        }
        let (dir, limits) = (self.0.scene_dir.clone(), self.0.scene_limits);
        let unpacked = dir.join(hash.to_string());
        // The bundle moves to the loading thread and its bytes come back with the
        // scene: no copy of a scene that may be hundreds of megabytes.
        let files = unpacked.clone();
        let loaded = tokio::task::spawn_blocking(move || {
            let loaded = bundle.load(&dir, &limits);
            if loaded.is_err() {
                // (Before answering: a failed load leaves nothing behind.)
                remove_dir(&files);
            }
            loaded.map(|scene| (scene, bundle.encoded))
        })
        .await
        .map_err(|e| Status::internal(format!("loading the scene: {e}")))?;
        let (scene, encoded) = match loaded {
            Ok(loaded) => loaded,
            Err(e) => {
                // (Paths as the bundle names them: where the server keeps scenes is
                // none of the caller's business.)
                let message = e.to_string().replace(&format!("{}/", unpacked.display()), "");
                return Err(Status::invalid_argument(format!(
                    "the scene does not load: {message}"
                )));
            }
        };
        let objects = scene
            .objects
            .iter()
            .map(|o| {
                let stored = StoredObject {
                    bounds: o.local_bounds,
                    mesh: o.hash,
                };
                (o.name.clone(), stored)
            })
            .collect();
        let stored = StoredScene {
            encoded: Arc::new(encoded),
            objects,
        };
        let added = self.0.state().add_scene(hash, stored, &caller.name);
        match added {
            Ok(evicted) => {
                tracing::info!(%hash, objects = scene.objects.len(), client = %caller.name, evicted = evicted.len(), "scene stored");
                remove_scene_files(
                    evicted
                        .iter()
                        .map(|h| self.0.scene_dir.join(h.to_string()))
                        .collect(),
                );
            }
            Err(refusal) => {
                remove_scene_files(vec![unpacked]);
                return Err(Status::resource_exhausted(refusal.to_string()));
            }
        }
        Ok(Response::new(pb::SceneRef {
            hash: hash.to_string(),
        }))
    }

    type GetSceneStream = BoxStream<pb::SceneChunk>;

    async fn get_scene(
        &self,
        request: Request<pb::SceneRef>,
    ) -> Result<Response<Self::GetSceneStream>, Status> {
        let caller = Caller::of(&request)?;
        let hash = hash_from_pb("hash", &request.get_ref().hash)?;
        // A client reads the scenes it uploaded; a worker, those it holds a job on. (Not
        // found either way: another's scene is not said to exist.)
        let scene = {
            let mut state = self.0.state();
            let as_client = match caller.may(Role::Client) {
                true => state.scene_of(&hash, &caller.name),
                false => None,
            };
            match (as_client, caller.may(Role::Worker)) {
                // (One credential in both roles — open, or one shared token — may be a
                // worker loading it.)
                (Some(scene), true) => {
                    state.worker_fetches(&hash, &caller.name);
                    Some(scene)
                }
                (Some(scene), false) => Some(scene),
                (None, true) => state.scene_for_worker(&hash, &caller.name),
                (None, false) => None,
            }
        }
        .ok_or_else(|| Status::not_found(format!("no scene with hash {hash} for this credential")))?;
        let encoded = scene.encoded.clone();
        let pieces: Vec<Result<pb::SceneChunk, Status>> = encoded
            .chunks(SCENE_CHUNK_BYTES)
            .map(|c| Ok(pb::SceneChunk { data: c.to_vec() }))
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(pieces))))
    }
}

#[tonic::async_trait]
impl pb::impostors_server::Impostors for Service {
    type RequestStream = ResultStream;

    async fn request(
        &self,
        request: Request<pb::ImpostorRequest>,
    ) -> Result<Response<Self::RequestStream>, Status> {
        let began = std::time::Instant::now();
        let caller = Caller::of(&request)?;
        let mut r =
            request_from_pb(request.get_ref()).inspect_err(|e| self.0.state().count_refusal(e.code()))?;
        // Requests are the credential's: another cannot withdraw them by naming the id.
        r.client_id = scoped(&caller, &r.client_id);
        let span =
            tracing::info_span!("request", client = %r.client_id, id = r.request_id, object = %r.object);
        let _entered = span.enter();
        let (tx, rx) = unbounded_channel();
        let mut state = self.0.state();
        let admission = state.admit(&r, &caller.name, tx.clone());
        if let Err(e) = &admission {
            tracing::info!(code = ?e.code(), "refused: {}", e.message());
            state.count_refusal(e.code());
        }
        match admission? {
            Admission::Cached(texture) => {
                let _ = tx.send(Ok(pb::ImpostorResult {
                    request_id: r.request_id,
                    texture: Some((*texture).clone()),
                    r#final: true,
                    bake_ms: 0,
                }));
            }
            Admission::Queued => state.dispatch(),
        }
        state.record_handling(began.elapsed().as_secs_f32() * 1e6);
        tracing::debug!(urgency = ?r.urgency, "admitted");
        // Only the state keeps a sender now: the stream ends when the request does.
        let sender = tx.downgrade();
        drop(tx);
        Ok(Response::new(ResultStream {
            results: UnboundedReceiverStream::new(rx),
            sender,
            shared: self.0.clone(),
            client_id: r.client_id.clone(),
            request_id: r.request_id,
            reads_planes: r.reads_planes,
        }))
    }

    async fn withdraw(
        &self,
        request: Request<pb::WithdrawRequest>,
    ) -> Result<Response<pb::WithdrawReply>, Status> {
        let caller = Caller::of(&request)?;
        let r = request.get_ref();
        check_client_id(&r.client_id)?;
        let mut state = self.0.state();
        let withdrawn = state.withdraw(&scoped(&caller, &r.client_id), &r.request_ids);
        state.dispatch();
        Ok(small(pb::WithdrawReply { withdrawn }))
    }

    async fn stats(&self, _: Request<pb::StatsRequest>) -> Result<Response<pb::StatsReply>, Status> {
        Ok(small(self.0.state().stats()))
    }
}

#[tonic::async_trait]
impl pb::workers_server::Workers for Service {
    type SessionStream = UnboundedReceiverStream<Result<pb::ServerMessage, Status>>;

    async fn session(
        &self,
        request: Request<Streaming<pb::WorkerMessage>>,
    ) -> Result<Response<Self::SessionStream>, Status> {
        let caller = Caller::of(&request)?;
        let mut inbound = request.into_inner();
        let register = match inbound.message().await?.and_then(|m| m.kind) {
            Some(pb::worker_message::Kind::Register(r)) => r,
            _ => {
                return Err(Status::invalid_argument(
                    "field `kind`: a session must start with `register`",
                ));
            }
        };
        check_register(&register)?;
        let (tx, rx) = unbounded_channel();
        let id = {
            let mut state = self.0.state();
            let id = state.add_worker(
                register.name.clone(),
                caller.name.clone(),
                register.slots as usize,
                register.threads,
                tx,
            );
            state.dispatch();
            id
        };
        tracing::info!(worker = %register.name, slots = register.slots, threads = register.threads, "worker registered");
        let shared = self.0.clone();
        tokio::spawn(async move {
            while let Ok(Some(message)) = inbound.message().await {
                let began = std::time::Instant::now();
                let is_result = matches!(message.kind, Some(pb::worker_message::Kind::Result(_)));
                // A result's texture is checked before the state's lock is taken: it is
                // the costliest step here, and needs no state.
                let texture = match &message.kind {
                    Some(pb::worker_message::Kind::Result(r)) => Some(match &r.texture {
                        Some(t) => check_texture_pb("texture", t).map_err(|e| e.message().to_string()),
                        None => Err("a result without a texture".to_string()),
                    }),
                    _ => None,
                };
                let mut state = shared.state();
                state.touch(id);
                // Which job the message answers for, if any.
                let job = match &message.kind {
                    Some(pb::worker_message::Kind::Result(r)) => Some(r.job_id),
                    Some(pb::worker_message::Kind::Failed(f)) => Some(f.job_id),
                    Some(pb::worker_message::Kind::Stopped(s)) => Some(s.job_id),
                    _ => None,
                };
                // A worker answers only for its own jobs, and with the texture asked for.
                let forgery = match (job, &message.kind, texture) {
                    (Some(job_id), _, _) if !state.holds(id, job_id) => {
                        Some(format!("job {job_id} is not leased to this worker"))
                    }
                    (Some(job_id), Some(pb::worker_message::Kind::Result(r)), Some(checked)) => checked
                        .and_then(|(camera, bits, eye)| {
                            state.check_result(job_id, &camera, bits, eye, r.r#final)
                        })
                        .err(),
                    _ => None,
                };
                if let Some(reason) = forgery {
                    state.forged(id, Status::permission_denied(reason));
                    state.dispatch();
                    return;
                }
                // The job the worker is now done with, if any (its slot held after a
                // cancel is free again).
                let done = match &message.kind {
                    Some(pb::worker_message::Kind::Result(r)) if r.r#final => job,
                    Some(pb::worker_message::Kind::Result(_)) => None,
                    _ => job,
                };
                match message.kind {
                    Some(pb::worker_message::Kind::Result(r)) => {
                        let texture = r.texture.unwrap_or_default();
                        state.result(r.job_id, texture, r.r#final, r.bake_ms);
                    }
                    Some(pb::worker_message::Kind::Failed(f)) => state.failed(f.job_id, &f.reason),
                    Some(pb::worker_message::Kind::Stopped(_)) => state.stopped(),
                    Some(pb::worker_message::Kind::Draining(_)) => state.draining(id),
                    Some(pb::worker_message::Kind::Heartbeat(_))
                    | Some(pb::worker_message::Kind::Register(_))
                    | None => {}
                }
                if let Some(job_id) = done {
                    state.released(id, job_id);
                }
                state.dispatch();
                if is_result {
                    state.record_handling(began.elapsed().as_secs_f32() * 1e6);
                }
            }
            let mut state = shared.state();
            state.remove_worker(id);
            state.dispatch();
        });
        Ok(Response::new(UnboundedReceiverStream::new(rx)))
    }
}
