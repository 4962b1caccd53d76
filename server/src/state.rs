//! The server's state: scenes, jobs, waiters, workers, cache and counters, changed only
//! under one lock by the methods here (no `await` inside), so every rule of the
//! scheduler lives in this file.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::mpsc::UnboundedSender;
use tonic::Status;

use relief_core::bounds::Aabb;
use relief_core::hash::ContentHash;
use relief_core::relief::{FacingError, SourceCamera};
use relief_core::stats::sorted_percentile;
use relief_proto::convert::{Request, Urgency, vec3_to_pb};
use relief_proto::pb;

/// What a waiting client receives: results, or the error that ends its request.
pub type ResultSender = UnboundedSender<Result<pb::ImpostorResult, Status>>;
/// What a worker receives.
pub type JobSender = UnboundedSender<Result<pb::ServerMessage, Status>>;

/// A stored scene: its encoded bundle and the bounds of its objects (enough to check
/// requests without loading meshes again).
#[derive(Debug)]
pub struct StoredScene {
    pub encoded: Arc<Vec<u8>>,
    pub objects: HashMap<String, Aabb>,
}

/// Where a texture is made from: the scene, the object and the eye. Textures of one
/// view differ only in their texel count and depth bits.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct View {
    scene: ContentHash,
    object: String,
    eye: [u32; 3],
}

/// What a job makes, or a request asks for: a view, at a size and depth.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct JobKey {
    view: View,
    size: u32,
    depth_bits: u32,
}

impl JobKey {
    fn of(r: &Request) -> JobKey {
        JobKey {
            view: View {
                scene: r.scene,
                object: r.object.clone(),
                eye: r.eye.to_array().map(f32::to_bits),
            },
            size: r.size,
            depth_bits: r.depth_bits.bits(),
        }
    }

    /// Whether the texture made for `self` serves a request for `wanted`: the same
    /// view, with at least its depth bits and its edge, up to [`MAX_SERVED_RATIO`]
    /// times it (a client draws the pyramid level its screen needs, so more texels cost
    /// it bytes on the wire, not warp time).
    fn satisfies(&self, wanted: &JobKey) -> bool {
        self.view == wanted.view
            && self.depth_bits >= wanted.depth_bits
            && (wanted.size..=wanted.size.saturating_mul(MAX_SERVED_RATIO)).contains(&self.size)
    }
}

/// How many times a request's edge a texture that serves it may be: 2 (4× the texels).
/// A far bigger one would cost a small request's client far more bytes — and, still
/// being made, far more waiting than a bake of its own.
const MAX_SERVED_RATIO: u32 = 2;

/// Queue order: needed-now first, then nearest deadline, then arrival.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Priority {
    predicted: bool,
    deadline_us: u64,
    id: u64,
}

#[derive(Debug)]
enum JobState {
    Queued(Priority),
    Running { worker: u64 },
}

#[derive(Debug)]
struct Job {
    key: JobKey,
    spec: pb::Job,
    state: JobState,
    waiters: HashSet<WaiterId>,
}

/// A client's request: `(client_id, request_id)`.
pub type WaiterId = (String, u64);

#[derive(Debug)]
struct Waiter {
    job: u64,
    tx: ResultSender,
    arrived: Instant,
}

#[derive(Debug)]
struct Worker {
    name: String,
    slots: usize,
    /// Threads each of its jobs bakes on (as it says; for Stats).
    threads: u32,
    running: HashSet<u64>,
    /// Jobs it was told to stop and has not yet said it stopped (or finished): their
    /// slots stay taken, so a worker that hangs is not handed job after job.
    stopping: HashSet<u64>,
    /// It said it is stopping: no new jobs.
    draining: bool,
    tx: JobSender,
    last_seen: Instant,
}

impl Worker {
    /// Slots taken: jobs running, and cancelled ones it has not answered for.
    fn busy(&self) -> usize {
        self.running.len() + self.stopping.len()
    }
}

/// A finished texture kept for reuse.
#[derive(Debug)]
struct Cached {
    key: JobKey,
    texture: Arc<pb::ReliefTexture>,
    bytes: usize,
    used: u64,
}

/// Counters a person can read (see `Stats` in the protocol).
#[derive(Debug, Default, Clone)]
pub struct Counters {
    pub requests: u64,
    pub cache_hits: u64,
    pub merged: u64,
    pub withdrawn: u64,
    pub requeued: u64,
    /// Cancelled jobs their workers stopped before finishing.
    pub stopped: u64,
    /// Requests ended by [`Limits::job_timeout`].
    pub timed_out: u64,
    /// Results that came for jobs no longer wanted.
    pub discarded: u64,
}

/// Upper bounds (ms) of the request latency histogram in [`pb::StatsReply`].
pub const LATENCY_BUCKETS_MS: [f32; 12] = [
    1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0,
];

/// Limits of the server.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Result cache size in bytes.
    pub cache_bytes: usize,
    /// A worker silent for this long loses its jobs to others.
    pub lease: Duration,
    /// Most requests waiting at once.
    pub max_waiting: usize,
    /// A request waiting this long ends with an error: none waits for ever, with no
    /// worker connected or on one that keeps its lease but never finishes.
    pub job_timeout: Duration,
}

/// Everything the server knows.
pub struct State {
    limits: Limits,
    epoch: Instant,
    scenes: HashMap<ContentHash, Arc<StoredScene>>,
    jobs: HashMap<u64, Job>,
    queue: BTreeSet<Priority>,
    /// The jobs of each view (a few: one per size and depth asked for).
    by_view: HashMap<View, Vec<u64>>,
    waiters: HashMap<WaiterId, Waiter>,
    workers: HashMap<u64, Worker>,
    /// The cached textures of each view.
    cache: HashMap<View, Vec<Cached>>,
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
    handling: VecDeque<f32>,
    pub counters: Counters,
}

/// How a request was taken in.
#[derive(Debug)]
pub enum Admission {
    /// Served from the cache: this texture, now.
    Cached(Arc<pb::ReliefTexture>),
    /// Queued (or merged into a queued or running job); results follow on the sender.
    Queued,
}

const LATENCY_SAMPLES: usize = 10_000;

/// Appends to a bounded window of recent samples.
fn push_sample(samples: &mut VecDeque<f32>, value: f32) {
    if samples.len() == LATENCY_SAMPLES {
        samples.pop_front();
    }
    samples.push_back(value);
}

impl State {
    pub fn new(limits: Limits) -> State {
        State {
            limits,
            epoch: Instant::now(),
            scenes: HashMap::new(),
            jobs: HashMap::new(),
            queue: BTreeSet::new(),
            by_view: HashMap::new(),
            waiters: HashMap::new(),
            workers: HashMap::new(),
            cache: HashMap::new(),
            recency: BTreeMap::new(),
            cache_bytes: 0,
            next_id: 1,
            clock: 0,
            latencies: VecDeque::new(),
            latency_counts: [0; LATENCY_BUCKETS_MS.len() + 1],
            handling: VecDeque::new(),
            counters: Counters::default(),
        }
    }

    fn next(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }

    pub fn add_scene(&mut self, hash: ContentHash, scene: StoredScene) {
        self.scenes.insert(hash, Arc::new(scene));
    }

    pub fn scene(&self, hash: &ContentHash) -> Option<Arc<StoredScene>> {
        self.scenes.get(hash).cloned()
    }

    /// Takes a validated request in: checks the scene, object and eye, answers from
    /// the cache, merges it into a job that satisfies it, or queues a new job.
    pub fn admit(&mut self, request: &Request, tx: ResultSender) -> Result<Admission, Status> {
        let scene = self.scenes.get(&request.scene).ok_or_else(|| {
            Status::not_found(format!("no scene with hash {} (upload it first)", request.scene))
        })?;
        let bounds = scene.objects.get(&request.object).ok_or_else(|| {
            Status::not_found(format!("the scene has no object named `{}`", request.object))
        })?;
        // The camera a worker would bake with: refused here, naming the field, rather
        // than failing on a worker.
        match SourceCamera::facing(request.eye, bounds, request.size, request.size) {
            Ok(_) => {}
            Err(FacingError::EyeInsideBounds) => {
                return Err(Status::failed_precondition(format!(
                    "the eye is inside the bounds of `{}`: draw it as geometry",
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
        let key = JobKey::of(request);
        self.clock += 1;
        let clock = self.clock;
        if let Some(hit) = self.cached_for(&key) {
            let last = std::mem::replace(&mut hit.used, clock);
            let (texture, hit_key) = (hit.texture.clone(), hit.key.clone());
            self.recency.remove(&last);
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
        let now = Instant::now();
        let deadline_us = now.duration_since(self.epoch).as_micros() as u64
            + match request.urgency {
                Urgency::Now => 0,
                Urgency::Predicted { in_ms } => in_ms.saturating_mul(1000),
            };
        let predicted = matches!(request.urgency, Urgency::Predicted { .. });
        let job_id = match self.job_for(&key) {
            Some(id) => {
                self.counters.merged += 1;
                // A more urgent request moves a queued job forward.
                if let Some(job) = self.jobs.get_mut(&id)
                    && let JobState::Queued(p) = job.state
                {
                    let better = Priority {
                        predicted: p.predicted && predicted,
                        deadline_us: p.deadline_us.min(deadline_us),
                        id,
                    };
                    if better != p {
                        self.queue.remove(&p);
                        self.queue.insert(better);
                        job.state = JobState::Queued(better);
                    }
                }
                id
            }
            None => {
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
                };
                self.jobs.insert(
                    id,
                    Job {
                        key: key.clone(),
                        spec,
                        state: JobState::Queued(priority),
                        waiters: HashSet::new(),
                    },
                );
                self.queue.insert(priority);
                self.by_view.entry(key.view).or_default().push(id);
                id
            }
        };
        if let Some(job) = self.jobs.get_mut(&job_id) {
            job.waiters.insert(waiter_id.clone());
            if request.progressive {
                job.spec.progressive = true;
            }
        }
        self.waiters.insert(
            waiter_id,
            Waiter {
                job: job_id,
                tx,
                arrived: now,
            },
        );
        Ok(Admission::Queued)
    }

    /// Registers a worker; returns its id.
    pub fn add_worker(&mut self, name: String, slots: usize, threads: u32, tx: JobSender) -> u64 {
        let id = self.next();
        self.workers.insert(
            id,
            Worker {
                name,
                slots,
                threads,
                running: HashSet::new(),
                stopping: HashSet::new(),
                draining: false,
                tx,
                last_seen: Instant::now(),
            },
        );
        id
    }

    /// The worker is alive.
    pub fn touch(&mut self, worker: u64) {
        if let Some(w) = self.workers.get_mut(&worker) {
            w.last_seen = Instant::now();
        }
    }

    /// The worker is gone: its running jobs go back to the queue, first in line.
    pub fn remove_worker(&mut self, worker: u64) {
        let Some(w) = self.workers.remove(&worker) else {
            return;
        };
        tracing::info!(worker = %w.name, jobs = w.running.len(), "worker left; re-queueing its jobs");
        for id in w.running {
            if let Some(job) = self.jobs.get_mut(&id) {
                let priority = Priority {
                    predicted: false,
                    deadline_us: 0,
                    id,
                };
                job.state = JobState::Queued(priority);
                self.queue.insert(priority);
                self.counters.requeued += 1;
            }
        }
    }

    /// Workers silent past their lease are removed (and their jobs re-queued).
    pub fn expire_leases(&mut self) {
        let lease = self.limits.lease;
        let expired: Vec<u64> = self
            .workers
            .iter()
            .filter(|(_, w)| w.last_seen.elapsed() > lease)
            .map(|(&id, _)| id)
            .collect();
        for id in expired {
            self.remove_worker(id);
        }
    }

    /// Hands queued jobs to workers with free slots, most urgent first. (A job whose
    /// clients have all gone is withdrawn before it gets here: see the service's
    /// `ResultStream`.)
    pub fn dispatch(&mut self) {
        loop {
            let Some(&first) = self.queue.first() else {
                return;
            };
            let Some((&worker_id, worker)) = self
                .workers
                .iter_mut()
                .filter(|(_, w)| !w.draining && w.busy() < w.slots)
                .min_by_key(|(_, w)| w.busy())
            else {
                return;
            };
            self.queue.remove(&first);
            let Some(job) = self.jobs.get_mut(&first.id) else {
                continue;
            };
            let message = pb::ServerMessage {
                kind: Some(pb::server_message::Kind::Job(job.spec.clone())),
            };
            if worker.tx.send(Ok(message)).is_err() {
                // The worker's stream is gone: put the job back and drop the worker.
                self.queue.insert(first);
                self.remove_worker(worker_id);
                continue;
            }
            worker.running.insert(first.id);
            job.state = JobState::Running { worker: worker_id };
        }
    }

    /// A worker's result. Previews go to the waiters; the final texture also goes to
    /// the cache and ends the job.
    pub fn result(&mut self, job_id: u64, texture: pb::ReliefTexture, is_final: bool, bake_ms: u32) {
        let Some(job) = self.jobs.get(&job_id) else {
            // Withdrawn meanwhile (and its worker not told in time, or unable to stop).
            self.counters.discarded += 1;
            return;
        };
        let texture = Arc::new(texture);
        for waiter_id in &job.waiters {
            if let Some(w) = self.waiters.get(waiter_id) {
                let result = pb::ImpostorResult {
                    request_id: waiter_id.1,
                    texture: Some((*texture).clone()),
                    r#final: is_final,
                    bake_ms,
                };
                let _ = w.tx.send(Ok(result));
            }
        }
        if is_final {
            let bytes = texture.albedo.len() + texture.normal.len() + texture.depth.len();
            let key = job.key.clone();
            self.cache_insert(key, texture, bytes);
            self.finish(job_id);
        }
    }

    /// A worker stopped a cancelled job before finishing it.
    pub fn stopped(&mut self) {
        self.counters.stopped += 1;
    }

    /// A worker could not make a texture: the waiters get the reason.
    pub fn failed(&mut self, job_id: u64, reason: &str) {
        if let Some(job) = self.jobs.get(&job_id) {
            let status = Status::aborted(format!("the worker failed: {reason}"));
            for waiter_id in &job.waiters {
                if let Some(w) = self.waiters.get(waiter_id) {
                    let _ = w.tx.send(Err(status.clone()));
                }
            }
        }
        self.finish(job_id);
    }

    /// Tells the worker running job `job_id`, if any, to stop it; its slot stays taken
    /// until the worker answers for the job ([`State::released`]).
    fn cancel_on_worker(&mut self, job_id: u64) {
        if let Some(job) = self.jobs.get(&job_id)
            && let JobState::Running { worker } = job.state
            && let Some(w) = self.workers.get_mut(&worker)
        {
            let cancel = pb::ServerMessage {
                kind: Some(pb::server_message::Kind::Cancel(pb::CancelJob { job_id })),
            };
            let _ = w.tx.send(Ok(cancel));
            w.stopping.insert(job_id);
        }
    }

    /// Worker `worker` is stopping: it gets no new jobs.
    pub fn draining(&mut self, worker: u64) {
        if let Some(w) = self.workers.get_mut(&worker) {
            w.draining = true;
        }
    }

    /// Worker `worker` is done with job `job_id` (its final result, failure or stop
    /// came): a slot held for it after a cancel is free again.
    pub fn released(&mut self, worker: u64, job_id: u64) {
        if let Some(w) = self.workers.get_mut(&worker) {
            w.stopping.remove(&job_id);
        }
    }

    /// Requests waiting longer than [`Limits::job_timeout`] end with DEADLINE_EXCEEDED
    /// (each by its own arrival: one merged into an old job gets the whole time); a
    /// job nobody waits for any more then ends, stopped on its worker.
    pub fn expire_jobs(&mut self) {
        let timeout = self.limits.job_timeout;
        let expired: Vec<WaiterId> = self
            .waiters
            .iter()
            .filter(|(_, w)| w.arrived.elapsed() > timeout)
            .map(|(id, _)| id.clone())
            .collect();
        let ms = timeout.as_millis();
        for waiter_id in expired {
            let running = self
                .waiters
                .get(&waiter_id)
                .and_then(|w| self.jobs.get(&w.job))
                .is_some_and(|j| matches!(j.state, JobState::Running { .. }));
            let reason = match running {
                true => format!("not finished within the job timeout ({ms} ms): a worker is still on it"),
                false => format!(
                    "no worker took it within the job timeout ({ms} ms); {} worker(s) connected",
                    self.workers.len()
                ),
            };
            if self.end_waiter(&waiter_id, Status::deadline_exceeded(reason)) {
                self.counters.timed_out += 1;
            }
        }
    }

    /// Ends request `waiter_id` before its job is done, with `status`; a job nobody
    /// waits for any more then ends too, stopped on its worker. Returns whether the
    /// request was waiting.
    fn end_waiter(&mut self, waiter_id: &WaiterId, status: Status) -> bool {
        let Some(waiter) = self.waiters.remove(waiter_id) else {
            return false;
        };
        let _ = waiter.tx.send(Err(status));
        if let Some(job) = self.jobs.get_mut(&waiter.job) {
            job.waiters.remove(waiter_id);
            if job.waiters.is_empty() {
                self.cancel_on_worker(waiter.job);
                self.finish(waiter.job);
            }
        }
        true
    }

    /// Ends a job: it leaves the queue or frees its worker's slot, and its waiters'
    /// streams close (their senders are dropped).
    fn finish(&mut self, job_id: u64) {
        let Some(job) = self.jobs.remove(&job_id) else {
            return;
        };
        if let Some(ids) = self.by_view.get_mut(&job.key.view) {
            ids.retain(|&id| id != job_id);
            if ids.is_empty() {
                self.by_view.remove(&job.key.view);
            }
        }
        match job.state {
            JobState::Queued(p) => {
                self.queue.remove(&p);
            }
            JobState::Running { worker } => {
                if let Some(w) = self.workers.get_mut(&worker) {
                    w.running.remove(&job_id);
                }
            }
        }
        for waiter_id in job.waiters {
            if let Some(w) = self.waiters.remove(&waiter_id) {
                self.latencies_push(w.arrived.elapsed().as_secs_f32() * 1e3);
            }
        }
    }

    /// Withdraws request `request_id` of `client_id` if its results still go to
    /// `results`: a stream dropped early withdraws its own request, never another
    /// that reuses the id. Returns whether it did.
    pub fn withdraw_own(&mut self, client_id: &str, request_id: u64, results: &ResultSender) -> bool {
        let own = self
            .waiters
            .get(&(client_id.to_string(), request_id))
            .is_some_and(|w| w.tx.same_channel(results));
        own && self.withdraw(client_id, &[request_id]) == 1
    }

    /// Withdraws requests; a job nobody waits for any more is cancelled (on its worker
    /// too). Returns how many requests were withdrawn.
    pub fn withdraw(&mut self, client_id: &str, request_ids: &[u64]) -> u32 {
        let mut withdrawn = 0;
        for &request_id in request_ids {
            if self.end_waiter(
                &(client_id.to_string(), request_id),
                Status::cancelled("withdrawn"),
            ) {
                withdrawn += 1;
                self.counters.withdrawn += 1;
            }
        }
        withdrawn
    }

    /// The smallest cached texture that serves `wanted`.
    fn cached_for(&mut self, wanted: &JobKey) -> Option<&mut Cached> {
        self.cache
            .get_mut(&wanted.view)?
            .iter_mut()
            .filter(|c| c.key.satisfies(wanted))
            .min_by_key(|c| c.bytes)
    }

    /// The job whose texture will serve `wanted`: a running one before a queued one
    /// (it finishes sooner), then the smallest.
    fn job_for(&self, wanted: &JobKey) -> Option<u64> {
        self.by_view
            .get(&wanted.view)?
            .iter()
            .filter_map(|id| Some((*id, self.jobs.get(id)?)))
            .filter(|(_, job)| job.key.satisfies(wanted))
            .min_by_key(|(_, job)| (matches!(job.state, JobState::Queued(_)), job.key.size))
            .map(|(id, _)| id)
    }

    fn cache_insert(&mut self, key: JobKey, texture: Arc<pb::ReliefTexture>, bytes: usize) {
        if bytes > self.limits.cache_bytes {
            return;
        }
        self.clock += 1;
        let entry = Cached {
            key,
            texture,
            bytes,
            used: self.clock,
        };
        self.recency.insert(self.clock, entry.key.clone());
        let entries = self.cache.entry(entry.key.view.clone()).or_default();
        match entries.iter_mut().find(|c| c.key == entry.key) {
            Some(old) => {
                self.cache_bytes -= old.bytes;
                self.recency.remove(&old.used);
                *old = entry;
            }
            None => entries.push(entry),
        }
        self.cache_bytes += bytes;
        // Least recently used first (the one just put in is the most recent, and fits
        // alone).
        while self.cache_bytes > self.limits.cache_bytes {
            let Some((_, key)) = self.recency.pop_first() else {
                break;
            };
            if let Some(entries) = self.cache.get_mut(&key.view) {
                if let Some(k) = entries.iter().position(|c| c.key == key) {
                    self.cache_bytes -= entries.swap_remove(k).bytes;
                }
                if entries.is_empty() {
                    self.cache.remove(&key.view);
                }
            }
        }
    }

    fn latencies_push(&mut self, ms: f32) {
        push_sample(&mut self.latencies, ms);
        let bucket = LATENCY_BUCKETS_MS.partition_point(|&bound| bound < ms);
        self.latency_counts[bucket] += 1;
    }

    /// Records the time (µs) the server's code spent on one request or result.
    pub fn record_handling(&mut self, us: f32) {
        push_sample(&mut self.handling, us);
    }

    /// The counters as the protocol's `StatsReply`.
    pub fn stats(&self) -> pb::StatsReply {
        let sorted = |samples: &VecDeque<f32>| {
            let mut v: Vec<f64> = samples.iter().map(|&s| f64::from(s)).collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let (latencies, handling) = (sorted(&self.latencies), sorted(&self.handling));
        // (0 before any sample, as the protocol says.)
        let percentile = |v: &[f64], p: f64| match sorted_percentile(v, p) {
            q if q.is_nan() => 0.0,
            q => q as f32,
        };
        let queued = |predicted: bool| self.queue.iter().filter(|p| p.predicted == predicted).count() as u32;
        pb::StatsReply {
            queue_now: queued(false),
            queue_predicted: queued(true),
            jobs_in_flight: self.workers.values().map(|w| w.running.len() as u32).sum(),
            workers: self.workers.len() as u32,
            requests: self.counters.requests,
            cache_hits: self.counters.cache_hits,
            merged: self.counters.merged,
            withdrawn: self.counters.withdrawn,
            requeued: self.counters.requeued,
            cache_bytes: self.cache_bytes as u64,
            latency_ms_p50: percentile(&latencies, 0.5),
            latency_ms_p99: percentile(&latencies, 0.99),
            handling_us_p50: percentile(&handling, 0.5),
            handling_us_p99: percentile(&handling, 0.99),
            jobs_stopped: self.counters.stopped,
            jobs_timed_out: self.counters.timed_out,
            latency_bucket_ms: LATENCY_BUCKETS_MS.to_vec(),
            latency_counts: self.latency_counts.to_vec(),
            worker_slots: self.workers.values().map(|w| w.slots as u32).sum(),
            worker_threads: self.workers.values().map(|w| w.threads).sum(),
            results_discarded: self.counters.discarded,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relief_core::relief::DepthBits;
    use tokio::sync::mpsc::unbounded_channel;

    fn state_with_scene() -> (State, ContentHash) {
        let mut s = State::new(Limits {
            cache_bytes: 1 << 20,
            lease: Duration::from_secs(5),
            max_waiting: 100,
            job_timeout: Duration::from_secs(60),
        });
        let hash = ContentHash([7; 32]);
        let bounds = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        s.add_scene(
            hash,
            StoredScene {
                encoded: Arc::new(vec![]),
                objects: [("ball".to_string(), bounds)].into_iter().collect(),
            },
        );
        (s, hash)
    }

    fn request(scene: ContentHash, id: u64, eye: Vec3, urgency: Urgency) -> Request {
        Request {
            scene,
            object: "ball".into(),
            eye,
            size: 16,
            depth_bits: DepthBits::Eight,
            urgency,
            client_id: "c".into(),
            request_id: id,
            progressive: false,
        }
    }

    /// Admits request `id` of client "c" for `hash`'s ball, needed now, from
    /// `(x, 0, 5)`.
    fn admit_now(s: &mut State, hash: ContentHash, id: u64, x: f32, results: ResultSender) {
        s.admit(&request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Now), results)
            .unwrap();
    }

    fn next_job(
        rx: &mut tokio::sync::mpsc::UnboundedReceiver<Result<pb::ServerMessage, Status>>,
    ) -> Option<pb::Job> {
        match rx.try_recv().ok()?.ok()?.kind? {
            pb::server_message::Kind::Job(j) => Some(j),
            pb::server_message::Kind::Cancel(_) => None,
        }
    }

    #[test]
    fn now_before_predicted_nearest_deadline_first_and_merging() {
        let (mut s, hash) = state_with_scene();
        let (tx, _rx) = unbounded_channel();
        let eye = |x: f32| Vec3::new(x, 0.0, 5.0);
        s.admit(
            &request(hash, 1, eye(1.0), Urgency::Predicted { in_ms: 900 }),
            tx.clone(),
        )
        .unwrap();
        s.admit(
            &request(hash, 2, eye(2.0), Urgency::Predicted { in_ms: 100 }),
            tx.clone(),
        )
        .unwrap();
        s.admit(&request(hash, 3, eye(3.0), Urgency::Now), tx.clone())
            .unwrap();
        // Same texture as request 2: merged.
        s.admit(
            &request(hash, 4, eye(2.0), Urgency::Predicted { in_ms: 50 }),
            tx.clone(),
        )
        .unwrap();
        assert_eq!(s.counters.merged, 1);
        let (wtx, mut wrx) = unbounded_channel();
        s.add_worker("w".into(), 3, 1, wtx);
        s.dispatch();
        let order: Vec<f32> = std::iter::from_fn(|| next_job(&mut wrx))
            .map(|j| j.eye.unwrap().x)
            .collect();
        assert_eq!(order, vec![3.0, 2.0, 1.0]);
    }

    /// One texture serves every request at its view for no more depth bits and at
    /// least half its edge: smaller requests join a bigger job, queued or running, and
    /// hit a bigger cached texture; a bigger one, one with more depth bits, or one far
    /// smaller gets a job of its own.
    #[test]
    fn a_bigger_texture_serves_smaller_requests() {
        let (mut s, hash) = state_with_scene();
        let (tx, mut rx) = unbounded_channel();
        let sized = |id: u64, size: u32, depth_bits: DepthBits| Request {
            size,
            depth_bits,
            ..request(hash, id, Vec3::new(1.0, 0.0, 5.0), Urgency::Now)
        };
        s.admit(&sized(1, 64, DepthBits::Sixteen), tx.clone()).unwrap();
        s.admit(&sized(2, 32, DepthBits::Eight), tx.clone()).unwrap();
        s.admit(&sized(3, 128, DepthBits::Eight), tx.clone()).unwrap();
        assert_eq!((s.counters.merged, s.stats().queue_now), (1, 2));
        let (wtx, mut wrx) = unbounded_channel();
        s.add_worker("w".into(), 1, 1, wtx);
        s.dispatch();
        let job = next_job(&mut wrx).unwrap();
        assert_eq!((job.size, job.depth_bits), (64, 16));
        // While it runs, a smaller request joins it.
        s.admit(&sized(4, 32, DepthBits::Eight), tx.clone()).unwrap();
        assert_eq!(s.counters.merged, 2);
        s.result(job.job_id, pb::ReliefTexture::default(), true, 1);
        let mut served: Vec<u64> = std::iter::from_fn(|| rx.try_recv().ok())
            .map(|r| r.unwrap().request_id)
            .collect();
        served.sort();
        assert_eq!(served, vec![1, 2, 4]);
        // Now cached: a smaller request is a hit, one with more depth bits is not.
        assert!(matches!(
            s.admit(&sized(5, 64, DepthBits::Eight), tx.clone()),
            Ok(Admission::Cached(_))
        ));
        s.admit(&sized(6, 128, DepthBits::Sixteen), tx.clone()).unwrap();
        assert_eq!(s.counters.cache_hits, 1);
        assert_eq!((s.counters.merged, s.stats().queue_now), (2, 2));
        // Nothing more than twice its edge serves a request: 16² gets a job of its own.
        s.admit(&sized(7, 16, DepthBits::Eight), tx.clone()).unwrap();
        assert_eq!(s.counters.cache_hits, 1);
        assert_eq!((s.counters.merged, s.stats().queue_now), (2, 3));
    }

    /// The cache keeps within its bytes by dropping the least recently used texture:
    /// a hit counts as a use.
    #[test]
    fn the_cache_drops_the_least_recently_used_texture() {
        let (mut s, hash) = state_with_scene();
        let (tx, _rx) = unbounded_channel();
        let (wtx, mut wrx) = unbounded_channel();
        s.add_worker("w".into(), 1, 1, wtx);
        // 300 kB each: three fit in the 1 MiB cache, four do not.
        let texture = || pb::ReliefTexture {
            albedo: vec![0; 300_000],
            ..Default::default()
        };
        let mut id = 0;
        let mut ask = |s: &mut State, x: f32| {
            id += 1;
            s.admit(
                &request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Now),
                tx.clone(),
            )
            .unwrap()
        };
        for x in [1.0, 2.0, 3.0] {
            ask(&mut s, x);
            s.dispatch();
            let job = next_job(&mut wrx).unwrap();
            s.result(job.job_id, texture(), true, 1);
        }
        assert_eq!(s.stats().cache_bytes, 900_000);
        // Eye 1 used again: eye 2 is now the least recent.
        assert!(matches!(ask(&mut s, 1.0), Admission::Cached(_)));
        ask(&mut s, 4.0);
        s.dispatch();
        let job = next_job(&mut wrx).unwrap();
        s.result(job.job_id, texture(), true, 1);
        assert_eq!(s.stats().cache_bytes, 900_000);
        for x in [1.0, 3.0, 4.0] {
            assert!(matches!(ask(&mut s, x), Admission::Cached(_)), "eye {x}");
        }
        assert!(!matches!(ask(&mut s, 2.0), Admission::Cached(_)));
        assert_eq!(s.counters.cache_hits, 4);
    }

    #[test]
    fn a_stream_withdraws_only_its_own_request() {
        let (mut s, hash) = state_with_scene();
        let (mine, _rx) = unbounded_channel();
        admit_now(&mut s, hash, 7, 0.0, mine.clone());
        // Another stream that used the same id (answered from the cache, say).
        let (other, _other_rx) = unbounded_channel();
        assert!(!s.withdraw_own("c", 7, &other));
        assert_eq!(s.stats().queue_now, 1);
        assert!(s.withdraw_own("c", 7, &mine));
        assert_eq!(s.stats().queue_now, 0);
    }

    /// Past the job timeout a queued job (no worker) and a running one (a worker that
    /// never finishes) both end in DEADLINE_EXCEEDED, the running one cancelled on its
    /// worker; a job within the timeout is left alone.
    #[test]
    fn jobs_past_the_timeout_end_in_an_error() {
        let (mut s, hash) = state_with_scene();
        let (tx1, mut rx1) = unbounded_channel();
        let (tx2, mut rx2) = unbounded_channel();
        admit_now(&mut s, hash, 1, 0.0, tx1);
        admit_now(&mut s, hash, 2, 1.0, tx2);
        let (wtx, mut wrx) = unbounded_channel();
        let w = s.add_worker("w".into(), 1, 1, wtx);
        s.dispatch();
        let running = next_job(&mut wrx).unwrap();
        s.expire_jobs();
        assert_eq!(s.stats().jobs_timed_out, 0);
        s.limits.job_timeout = Duration::ZERO;
        s.expire_jobs();
        for rx in [&mut rx1, &mut rx2] {
            let status = rx.try_recv().unwrap().unwrap_err();
            assert_eq!(status.code(), tonic::Code::DeadlineExceeded, "{status:?}");
        }
        match wrx.try_recv().unwrap().unwrap().kind.unwrap() {
            pb::server_message::Kind::Cancel(c) => assert_eq!(c.job_id, running.job_id),
            other => panic!("expected a cancel, got {other:?}"),
        }
        let stats = s.stats();
        assert_eq!(
            (stats.jobs_timed_out, stats.queue_now, stats.jobs_in_flight),
            (2, 0, 0)
        );
        // Each request has the whole timeout: one merged into an old job outlives the
        // first, and the job goes on for it. (The worker has answered for the first.)
        s.released(w, running.job_id);
        s.limits.job_timeout = Duration::from_millis(100);
        let eye = Vec3::new(2.0, 0.0, 5.0);
        let (tx3, mut rx3) = unbounded_channel();
        let (tx4, mut rx4) = unbounded_channel();
        s.admit(&request(hash, 3, eye, Urgency::Now), tx3).unwrap();
        s.dispatch();
        std::thread::sleep(Duration::from_millis(150));
        s.admit(&request(hash, 4, eye, Urgency::Now), tx4).unwrap();
        assert_eq!(s.stats().merged, 1);
        s.expire_jobs();
        assert_eq!(
            rx3.try_recv().unwrap().unwrap_err().code(),
            tonic::Code::DeadlineExceeded
        );
        assert!(rx4.try_recv().is_err(), "the later request is still waiting");
        assert_eq!(s.stats().jobs_in_flight, 1);
    }

    /// A latency on a bucket's bound counts in that bucket; above the last, in the
    /// extra one.
    #[test]
    fn the_latency_histogram_counts_bounds_in_their_bucket() {
        let (mut s, _) = state_with_scene();
        for ms in [0.5, 1.0, 1.5, 5000.0, 5000.5] {
            s.latencies_push(ms);
        }
        let counts = s.stats().latency_counts;
        assert_eq!(counts.len(), LATENCY_BUCKETS_MS.len() + 1);
        assert_eq!((counts[0], counts[1], counts[11], counts[12]), (2, 1, 1, 1));
        assert_eq!(counts.iter().sum::<u64>(), 5);
    }

    /// A cancelled job keeps its worker's slot until the worker answers for it: a
    /// worker that hangs is not handed the next job.
    #[test]
    fn a_cancelled_job_holds_its_slot_until_the_worker_answers() {
        let (mut s, hash) = state_with_scene();
        let (tx, _rx) = unbounded_channel();
        admit_now(&mut s, hash, 1, 0.0, tx.clone());
        let (wtx, mut wrx) = unbounded_channel();
        let w = s.add_worker("w".into(), 1, 1, wtx);
        s.dispatch();
        let first = next_job(&mut wrx).unwrap();
        assert_eq!(s.withdraw("c", &[1]), 1);
        admit_now(&mut s, hash, 2, 1.0, tx);
        s.dispatch();
        assert!(matches!(
            wrx.try_recv().unwrap().unwrap().kind,
            Some(pb::server_message::Kind::Cancel(_))
        ));
        assert!(
            wrx.try_recv().is_err(),
            "a job went to a worker still on a cancelled one"
        );
        assert_eq!(s.stats().queue_now, 1);
        s.released(w, first.job_id);
        s.dispatch();
        assert!(next_job(&mut wrx).is_some());
    }

    #[test]
    fn withdrawal_cancels_queued_and_running_jobs() {
        let (mut s, hash) = state_with_scene();
        let (tx, _rx) = unbounded_channel();
        admit_now(&mut s, hash, 1, 0.0, tx.clone());
        admit_now(&mut s, hash, 2, 1.0, tx.clone());
        let (wtx, mut wrx) = unbounded_channel();
        s.add_worker("w".into(), 1, 1, wtx);
        s.dispatch();
        let running = next_job(&mut wrx).unwrap();
        assert_eq!(s.withdraw("c", &[1, 2, 99]), 2);
        // The running one is cancelled on the worker; nothing is left queued.
        match wrx.try_recv().unwrap().unwrap().kind.unwrap() {
            pb::server_message::Kind::Cancel(c) => assert_eq!(c.job_id, running.job_id),
            other => panic!("expected a cancel, got {other:?}"),
        }
        assert_eq!(s.stats().queue_now, 0);
        assert_eq!(s.stats().jobs_in_flight, 0);
    }

    #[test]
    fn a_vanished_workers_jobs_are_requeued_and_bad_requests_refused() {
        let (mut s, hash) = state_with_scene();
        let (tx, _rx) = unbounded_channel();
        admit_now(&mut s, hash, 1, 0.0, tx.clone());
        let (wtx, _wrx) = unbounded_channel();
        let w = s.add_worker("w".into(), 1, 1, wtx);
        s.dispatch();
        assert_eq!(s.stats().jobs_in_flight, 1);
        s.remove_worker(w);
        assert_eq!((s.stats().queue_now, s.counters.requeued), (1, 1));
        let inside = s
            .admit(&request(hash, 2, Vec3::ZERO, Urgency::Now), tx.clone())
            .unwrap_err();
        assert_eq!(inside.code(), tonic::Code::FailedPrecondition);
        let mut unknown = request(hash, 3, Vec3::new(0.0, 0.0, 5.0), Urgency::Now);
        unknown.object = "cube".into();
        assert_eq!(
            s.admit(&unknown, tx.clone()).unwrap_err().code(),
            tonic::Code::NotFound
        );
        unknown.scene = ContentHash([1; 32]);
        assert_eq!(s.admit(&unknown, tx).unwrap_err().code(), tonic::Code::NotFound);
    }
}
