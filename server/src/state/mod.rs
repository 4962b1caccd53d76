//! The server's state: scenes, jobs, waiters, workers, cache and counters, changed only
//! under one lock by the methods of [`State`] (no `await` inside), so every rule of the
//! scheduler lives in this folder, one concern a file:
//!
//! - here — a request's admission (served from the cache, joined to a job that
//!   satisfies it, or queued);
//! - `scenes.rs` — the scenes stored, who uploaded each, bounded in bytes;
//! - `queue.rs` — the jobs waiting, one line per client credential, served fairly;
//! - `jobs.rs` — dispatch to workers, results, failures, timeouts,
//!   withdrawals;
//! - `workers.rs` — registration, leases, draining;
//! - `cache.rs` — finished textures kept for reuse, bounded in bytes, least recently used
//!   out first;
//! - `stats.rs` — the counters and latency figures of `Impostors.Stats`.

mod admission;
mod cache;
mod jobs;
mod queue;
mod scenes;
pub mod stats;
mod workers;

#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::mpsc::UnboundedSender;
use tonic::Status;

use relief_core::relief::{FacingError, SourceCamera};
use relief_proto::convert::{Request, Urgency, projection_to_pb, vec3_to_pb};
use relief_proto::pb;

pub use jobs::{JobKey, WaiterId};
pub use stats::{Counters, LATENCY_BUCKETS_MS};

use cache::Cached;
use jobs::{Job, JobState, Subject, Waiter, Wanted};
use queue::{FairQueue, Priority};
use scenes::Scenes;
pub use scenes::{SceneRefusal, StoredObject, StoredScene};
use workers::Worker;

/// What a waiting client receives: results, or the error that ends its request.
pub type ResultSender = UnboundedSender<Result<pb::ImpostorResult, Status>>;
/// What a worker receives.
pub type JobSender = UnboundedSender<Result<pb::ServerMessage, Status>>;

/// Limits of the server.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Result cache size in bytes.
    pub cache_bytes: usize,
    /// A worker silent for this long loses its jobs to others.
    pub lease: Duration,
    /// Most requests waiting at once.
    pub max_waiting: usize,
    /// Most requests one client (credential) has waiting at once.
    pub max_waiting_per_client: usize,
    /// A job whose worker shows no progress (a preview or the final texture) for this
    /// long is taken back and queued for another.
    pub job_progress: Duration,
    /// Scenes stored, bytes of their bundles: past it the least recently used scene
    /// no job needs is evicted.
    pub scene_store_bytes: usize,
    /// A request waiting this long ends with an error: none waits for ever, with no
    /// worker connected or on one that keeps its lease but never finishes.
    pub job_timeout: Duration,
}

/// Everything the server knows.
pub struct State {
    limits: Limits,
    epoch: Instant,
    /// Chosen at random at start ([`instance_id`]): a client seeing it change knows the
    /// server restarted and lost the scenes it held.
    instance: u64,
    scenes: Scenes,
    jobs: HashMap<u64, Job>,
    queue: FairQueue,
    /// The jobs of each subject, oldest first.
    by_subject: HashMap<Subject, Vec<u64>>,
    waiters: HashMap<WaiterId, Waiter>,
    /// Requests waiting, per client credential (see [`Limits::max_waiting_per_client`]).
    waiting_by_owner: HashMap<Arc<str>, usize>,
    workers: HashMap<u64, Worker>,
    /// The cached textures of each subject.
    cache: HashMap<Subject, Vec<Cached>>,
    /// The cached textures by their last use (the clock), least recent first: what
    /// eviction takes, without a scan of the cache.
    recency: BTreeMap<u64, JobKey>,
    cache_bytes: usize,
    next_id: u64,
    clock: u64,
    latencies: VecDeque<f32>,
    /// Every request latency since start, counted in [`LATENCY_BUCKETS_MS`] (the last
    /// count: above the last bound).
    latency_counts: [u64; LATENCY_BUCKETS_MS.len() + 1],
    /// The sum of those latencies, ms (a histogram's `_sum`).
    latency_sum_ms: f64,
    /// How long the latest jobs held their slots, seconds (see [`admission`]).
    job_times: VecDeque<f64>,
    /// The foreseen wait's mean over time, seconds, and when it was last updated.
    mean_wait_s: f64,
    mean_wait_at: Option<Instant>,
    handling: VecDeque<f32>,
    pub counters: Counters,
}

/// A number unlikely to repeat across the server's starts: the clock hashed with the
/// process's random hashing keys (which the standard library seeds from the OS).
fn instance_id() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    let since_epoch = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    hasher.write_u128(since_epoch.as_nanos());
    hasher.write_u32(std::process::id());
    hasher.finish().max(1)
}

/// How a request was taken in.
#[derive(Debug)]
pub enum Admission {
    /// Served from the cache: this texture, now.
    Cached(Arc<pb::ReliefTexture>),
    /// Queued (or merged into a queued or running job); results follow on the sender.
    Queued,
}

impl State {
    pub fn new(limits: Limits) -> State {
        State {
            limits,
            epoch: Instant::now(),
            instance: instance_id(),
            scenes: Scenes::default(),
            jobs: HashMap::new(),
            queue: FairQueue::default(),
            by_subject: HashMap::new(),
            waiters: HashMap::new(),
            waiting_by_owner: HashMap::new(),
            workers: HashMap::new(),
            cache: HashMap::new(),
            recency: BTreeMap::new(),
            cache_bytes: 0,
            next_id: 1,
            clock: 0,
            latencies: VecDeque::new(),
            latency_counts: [0; LATENCY_BUCKETS_MS.len() + 1],
            latency_sum_ms: 0.0,
            job_times: VecDeque::new(),
            mean_wait_s: 0.0,
            mean_wait_at: None,
            handling: VecDeque::new(),
            counters: Counters::default(),
        }
    }

    fn next(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }

    /// Takes a validated request of client `owner` in: checks the scene (one `owner`
    /// uploaded), object and eye, answers from the cache, merges it into a job that
    /// satisfies it, or queues a new job.
    pub fn admit(&mut self, request: &Request, owner: &str, tx: ResultSender) -> Result<Admission, Status> {
        let scene = self.scene_of(&request.scene, owner).ok_or_else(|| {
            Status::not_found(format!("no scene with hash {} (upload it first)", request.scene))
        })?;
        let object = scene.objects.get(&request.object).ok_or_else(|| {
            // (An argument the scene cannot take: `NOT_FOUND` is kept for a scene the
            // server does not hold, which a client mends by uploading it again.)
            Status::invalid_argument(format!(
                "object: the scene has no object named `{}`",
                request.object
            ))
        })?;
        // The camera a worker would bake with: refused here, naming the field, rather
        // than failing on a worker.
        let object = *object;
        match SourceCamera::facing(
            request.eye,
            &object.bounds,
            request.size,
            request.size,
            request.projection,
        ) {
            Ok(_) => {}
            Err(e @ (FacingError::EyeInsideBounds | FacingError::EyeTooNear)) => {
                return Err(Status::failed_precondition(format!(
                    "object `{}`: {e}",
                    request.object
                )));
            }
            Err(e @ FacingError::NonFiniteEye(_)) => {
                return Err(Status::invalid_argument(format!("field `eye`: {e}")));
            }
            Err(e) => {
                return Err(Status::invalid_argument(format!(
                    "field `eye` with object `{}`: {e}",
                    request.object
                )));
            }
        }
        self.counters.requests += 1;
        let key = JobKey::of(request, object.mesh);
        let wanted = Wanted {
            radius: request.serve_within * request.eye.distance(object.bounds.center()),
            key: key.clone(),
        };
        self.clock += 1;
        let clock = self.clock;
        if let Some(hit) = self.cached_for(&wanted) {
            let last = std::mem::replace(&mut hit.used, clock);
            let (texture, hit_key) = (hit.texture.clone(), hit.key.clone());
            self.recency.remove(&last);
            self.counters.served_nearby += u64::from(hit_key.eye() != key.eye());
            self.recency.insert(clock, hit_key);
            self.counters.cache_hits += 1;
            self.latencies_push(0.0);
            return Ok(Admission::Cached(texture));
        }
        let waiter_id = (request.client_id.clone(), request.request_id);
        if self.waiters.contains_key(&waiter_id) {
            return Err(Status::already_exists(format!(
                "request {} of client `{}` is already pending",
                request.request_id, request.client_id
            )));
        }
        if self.waiters.len() >= self.limits.max_waiting {
            return Err(Status::resource_exhausted(format!(
                "{} requests already waiting (the server's limit)",
                self.limits.max_waiting
            )));
        }
        let owner: Arc<str> = owner.into();
        let owned = self.waiting_by_owner.get(&owner).copied().unwrap_or(0);
        if owned >= self.limits.max_waiting_per_client {
            return Err(Status::resource_exhausted(format!(
                "this client already has {owned} requests waiting (the server's --max-waiting-per-client)"
            )));
        }
        let now = Instant::now();
        let deadline_us =
            (now.duration_since(self.epoch).as_micros() as u64).saturating_add(match request.urgency {
                Urgency::Now => 0,
                Urgency::Predicted { in_ms } => in_ms.saturating_mul(1000),
            });
        let predicted = matches!(request.urgency, Urgency::Predicted { .. });
        let job_id = match self.job_for(&wanted) {
            Some(id) => {
                self.counters.merged += 1;
                if let Some(job) = self.jobs.get_mut(&id) {
                    self.counters.served_nearby += u64::from(job.key.eye() != key.eye());
                    job.latest_need_us = job.latest_need_us.max(deadline_us);
                    // A more urgent request moves a queued job forward.
                    if let JobState::Queued(p) = job.state {
                        let better = Priority {
                            predicted: p.predicted && predicted,
                            deadline_us: p.deadline_us.min(deadline_us),
                            id,
                        };
                        if better != p {
                            self.queue.remove(&job.owner, &p);
                            self.queue.insert(&job.owner, better);
                            job.state = JobState::Queued(better);
                        }
                    }
                }
                id
            }
            None => {
                // A new job for a prediction the workers cannot finish in time is
                // refused (see `admission`); one joining a job already there costs
                // nothing more.
                self.track_wait();
                if let Urgency::Predicted { in_ms } = request.urgency
                    && let Some(wait) = self.too_late(in_ms)
                {
                    self.counters.shed += 1;
                    return Err(admission::saturated(
                        format!(
                            "saturated: a texture needed in {in_ms} ms would be ready in about {} ms",
                            wait.as_millis()
                        ),
                        wait,
                    ));
                }
                let id = self.next();
                let priority = Priority {
                    predicted,
                    deadline_us,
                    id,
                };
                let spec = pb::Job {
                    job_id: id,
                    scene_hash: request.scene.to_string(),
                    object: request.object.clone(),
                    eye: Some(vec3_to_pb(request.eye)),
                    size: request.size,
                    depth_bits: request.depth_bits.bits(),
                    progressive: request.progressive,
                    projection: projection_to_pb(request.projection).into(),
                };
                self.jobs.insert(
                    id,
                    Job {
                        owner: owner.clone(),
                        key: key.clone(),
                        spec,
                        state: JobState::Queued(priority),
                        waiters: HashSet::new(),
                        latest_need_us: deadline_us,
                        preempted: false,
                        loaded_scene: false,
                    },
                );
                self.queue.insert(&owner, priority);
                self.by_subject.entry(key.subject).or_default().push(id);
                id
            }
        };
        if let Some(job) = self.jobs.get_mut(&job_id) {
            job.waiters.insert(waiter_id.clone());
            if request.progressive {
                job.spec.progressive = true;
            }
        }
        *self.waiting_by_owner.entry(owner.clone()).or_default() += 1;
        self.waiters.insert(
            waiter_id,
            Waiter {
                owner,
                job: job_id,
                tx,
                arrived: now,
            },
        );
        Ok(Admission::Queued)
    }
}
