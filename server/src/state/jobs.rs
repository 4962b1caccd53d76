//! The job queue and a job's life: dispatch to a worker with a free slot, results and
//! failures, timeouts, and withdrawals by the clients that asked.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tonic::Status;

use glam::Vec3;
use relief_core::hash::ContentHash;
use relief_core::relief::{DepthBits, SourceCamera, SourceProjection};
use relief_proto::convert::Request;
use relief_proto::pb;

use super::queue::Priority;
use super::{ResultSender, State};

/// What a texture shows, whatever its eye: the scene, the object's mesh and the
/// projection. Placements of one mesh share their textures (eyes are in the mesh's
/// frame), and so do clients flying through one scene.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(super) struct Subject {
    pub(super) scene: ContentHash,
    pub(super) mesh: ContentHash,
    pub(super) projection: SourceProjection,
}

/// What a job makes, or a request asks for: a subject from an eye (in the object's
/// frame), at a size and depth.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct JobKey {
    pub(super) subject: Subject,
    /// The eye's bits: one key per eye, exactly.
    eye: [u32; 3],
    pub(super) size: u32,
    pub(super) depth_bits: u32,
}

/// A request's key, and how near another eye may be to serve it.
#[derive(Debug, Clone)]
pub(super) struct Wanted {
    pub(super) key: JobKey,
    /// The farthest (object-frame distance) the eye of a texture serving it may be from
    /// its own: the request's `serve_within` times its eye's distance from the
    /// object's centre.
    pub(super) radius: f32,
}

impl JobKey {
    /// The key of request `r` for an object whose mesh has content hash `mesh`.
    pub(super) fn of(r: &Request, mesh: ContentHash) -> JobKey {
        JobKey {
            subject: Subject {
                scene: r.scene,
                mesh,
                projection: r.projection,
            },
            eye: r.eye.to_array().map(f32::to_bits),
            size: r.size,
            depth_bits: r.depth_bits.bits(),
        }
    }

    /// The eye, in the object's frame.
    pub(super) fn eye(&self) -> Vec3 {
        Vec3::from_array(self.eye.map(f32::from_bits))
    }

    /// How far the eye of the texture made for `self` is from `wanted`'s, if that
    /// texture serves it: the same subject, an eye within its radius, at least its
    /// depth bits and its edge, up to [`MAX_SERVED_RATIO`] times it (a client draws
    /// the pyramid level its screen needs, so more texels cost it bytes on the wire,
    /// not warp time).
    pub(super) fn serves(&self, wanted: &Wanted) -> Option<f32> {
        let w = &wanted.key;
        let apart = if self.eye == w.eye {
            0.0
        } else {
            self.eye().distance(w.eye())
        };
        (self.subject == w.subject
            && apart <= wanted.radius
            && self.depth_bits >= w.depth_bits
            && (w.size..=w.size.saturating_mul(MAX_SERVED_RATIO)).contains(&self.size))
        .then_some(apart)
    }
}

/// How long a job told to stop counts as a slot coming free: a bake looks for a stop
/// every block of rays (milliseconds), so the answer takes about a round trip. Past it
/// the worker is hung on that job — its slot stays taken, but preemption no longer
/// waits for it (a hung worker's one unanswered stop turned preemption off for good).
pub const STOP_GRACE: Duration = Duration::from_secs(2);

/// Jobs of at most this many texels may run on a worker beside the jobs filling its
/// slots, one at a time, for a client with nothing running (`State::express_worker`):
/// such a bake takes about a millisecond on one core, so it slows the others by that
/// much, where taking a slot back (`State::preempt_for`) loses the work of the bake
/// stopped and costs a round trip — and a job taken back once is never taken back
/// again, so a second client's requests one after another waited, every other one,
/// for a whole restarted 1024² bake (a 32² request 2.3–15.9× its idle latency).
pub const EXPRESS_MAX_TEXELS: u32 = 64 * 64;

/// How many times a request's edge a texture that serves it may be: 2 (4× the texels).
/// A far bigger one would cost a small request's client far more bytes — and, still
/// being made, far more waiting than a bake of its own.
const MAX_SERVED_RATIO: u32 = 2;

/// The most jobs, and the most cached textures, of one [`Subject`] a request looks
/// through for one that serves it: each is an eye to compare, so this bounds a
/// request's lookup (tens of microseconds) however many a flood of requests left.
/// The cache keeps no more of one subject.
pub(super) const SUBJECT_SCAN: usize = 1024;

/// `texture` with its planes (as the worker sent them: ours compressed) in buffers of
/// their own, exactly their size: decoded from the wire they are slices of the whole
/// received message's buffer (larger, and kept alive as long as any slice is —
/// measured: the cache held about 1.8 times the bytes it counted). Copied once here,
/// they are then shared by every waiter and cache hit.
fn compact(texture: pb::ReliefTexture) -> pb::ReliefTexture {
    use tonic::codegen::Bytes;
    pb::ReliefTexture {
        albedo: Bytes::copy_from_slice(&texture.albedo),
        normal: Bytes::copy_from_slice(&texture.normal),
        depth: Bytes::copy_from_slice(&texture.depth),
        ..texture
    }
}

/// How far a result's texture camera may stray from the one its job's eye and object
/// give, relative to the object's size (or, for the texel steps, their length): a
/// worker on another machine may round differently, a texture made for another eye or
/// object misses by far more.
const CAMERA_SLACK: f32 = 1e-4;

#[derive(Debug)]
pub(super) enum JobState {
    Queued(Priority),
    /// On `worker` since `started`; the worker last showed progress on it (took it,
    /// or sent a preview) at `progress`.
    Running {
        worker: u64,
        started: Instant,
        progress: Instant,
    },
}

#[derive(Debug)]
pub(super) struct Job {
    /// The client credential whose request made it: the queue's line it waits in.
    pub(super) owner: Arc<str>,
    pub(super) key: JobKey,
    pub(super) spec: pb::Job,
    pub(super) state: JobState,
    pub(super) waiters: HashSet<WaiterId>,
    /// The latest need of its requests, µs since the state's epoch (a request needed
    /// now counts as needed at once): while it is queued, its priority keeps the
    /// earliest; it has outlived its use only when the latest has passed (see
    /// `State::outlived`).
    pub(super) latest_need_us: u64,
    /// It was taken back once for another client's request (see
    /// `State::preempt_for`): never again.
    pub(super) preempted: bool,
    /// Its worker fetched the job's scene while it held it (see
    /// `State::worker_fetches`): its time is the scene's load as much as a bake, and
    /// is not one the jobs to come will take (see `State::job_took`).
    pub(super) loaded_scene: bool,
}

/// A client's request: `(client_id, request_id)`.
pub type WaiterId = (String, u64);

#[derive(Debug)]
pub(super) struct Waiter {
    /// The client credential it counts against.
    pub(super) owner: Arc<str>,
    pub(super) job: u64,
    pub(super) tx: ResultSender,
    pub(super) arrived: Instant,
}

impl State {
    /// Hands queued jobs to workers with free slots, fairly across clients (see
    /// `queue.rs`). (A job whose clients have all gone is withdrawn before it gets here:
    /// see the service's `ResultStream`.)
    pub fn dispatch(&mut self) {
        loop {
            let Some((owner, first)) = self.queue.next() else {
                return;
            };
            let free = (self.workers.iter())
                .filter(|(_, w)| !w.draining && w.busy() < w.slots)
                .min_by_key(|(_, w)| w.busy())
                .map(|(&id, _)| id);
            let express = free
                .is_none()
                .then(|| self.express_worker(&owner, first))
                .flatten();
            let chosen = free.or(express);
            // A prediction the slot would start past its use is refused instead.
            if chosen.is_some()
                && let Some(late) = self.outlived(&first, Instant::now())
            {
                // (Out of the queue first, whatever the job's state says: the loop
                // must move on.)
                self.queue.remove(&owner, &first);
                self.shed_queued(first.id, late);
                continue;
            }
            let Some((worker_id, worker)) = chosen.and_then(|id| self.workers.get_mut(&id).map(|w| (id, w)))
            else {
                // (A slot taken back is lent at once: hand it out.)
                if self.preempt_for(&owner, first) {
                    continue;
                }
                return;
            };
            self.queue.remove(&owner, &first);
            let Some(job) = self.jobs.get_mut(&first.id) else {
                continue;
            };
            if express.is_some() {
                worker.beside.retain(|id| worker.running.contains(id));
                worker.beside.insert(first.id);
            }
            let message = pb::ServerMessage {
                kind: Some(pb::server_message::Kind::Job(job.spec.clone())),
            };
            if worker.tx.send(Ok(message)).is_err() {
                // The worker's stream is gone: put the job back and drop the worker.
                self.queue.insert(&owner, first);
                self.remove_worker(worker_id);
                continue;
            }
            worker.running.insert(first.id);
            let now = Instant::now();
            job.state = JobState::Running {
                worker: worker_id,
                started: now,
                progress: now,
            };
            self.queue.started(&owner);
        }
    }

    /// A worker's result. Previews go to the waiters; the final texture also goes to
    /// the cache and ends the job.
    pub fn result(&mut self, job_id: u64, texture: pb::ReliefTexture, is_final: bool, bake_ms: u32) {
        let Some(job) = self.jobs.get_mut(&job_id) else {
            // Withdrawn meanwhile (and its worker not told in time, or unable to stop).
            self.counters.discarded += 1;
            return;
        };
        if let JobState::Running { progress, .. } = &mut job.state {
            *progress = Instant::now();
        }
        let job = &*job;
        let texture = Arc::new(compact(texture));
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
            let started = match job.state {
                JobState::Running { started, .. } => Some(started),
                JobState::Queued(_) => None,
            };
            // (What the rim hides: four lists of `u32`s.)
            let hidden = 4 * size_of::<u32>() * texture.hidden_texels.len();
            let bytes = texture.albedo.len() + texture.normal.len() + texture.depth.len() + hidden;
            let key = job.key.clone();
            if let Some(started) = started
                && !job.loaded_scene
            {
                self.job_took(started);
            }
            self.cache_insert(key, texture, bytes);
            self.finish(job_id);
        }
    }

    /// Whether a result whose texture has `camera`, `bits` and `eye` (checked as a
    /// texture already) is what job `job_id` asked for: its edge (a preview's at most
    /// that), depth bits, eye, and the camera the job's object and eye give. A job no
    /// longer here (cancelled) takes any: its results are discarded.
    pub fn check_result(
        &self,
        job_id: u64,
        camera: &SourceCamera,
        bits: DepthBits,
        eye: Vec3,
        is_final: bool,
    ) -> Result<(), String> {
        let Some(job) = self.jobs.get(&job_id) else {
            return Ok(());
        };
        let spec = &job.spec;
        let size = spec.size;
        let (w, h) = (camera.width, camera.height);
        if w != h || w > size || (is_final && w != size) {
            return Err(format!(
                "job {job_id} asked for {size}² texels, the result has {w}×{h}"
            ));
        }
        if bits.bits() != spec.depth_bits {
            return Err(format!(
                "job {job_id} asked for {}-bit depth, the result has {}",
                spec.depth_bits,
                bits.bits()
            ));
        }
        if eye.to_array().map(f32::to_bits) != job.key.eye {
            return Err(format!(
                "the result of job {job_id} was made for another eye ({eye})"
            ));
        }
        let Some(bounds) = self.object_bounds(&job.key.subject.scene, &spec.object) else {
            return Ok(());
        };
        let expected = SourceCamera::facing(eye, &bounds, w, h, job.key.subject.projection)
            .map_err(|e| e.to_string())?;
        let extent = bounds.extent().length();
        let near = |a: Vec3, b: Vec3, scale: f32| a.distance(b) <= CAMERA_SLACK * scale;
        let fits = near(camera.origin, expected.origin, extent)
            && near(camera.a, expected.a, expected.a.length())
            && near(camera.b, expected.b, expected.b.length())
            && near(camera.f, expected.f, 1.0)
            && (camera.depth_near - expected.depth_near).abs() <= CAMERA_SLACK * extent
            && (camera.depth_far - expected.depth_far).abs() <= CAMERA_SLACK * extent
            && match (camera.centre, expected.centre) {
                (None, None) => true,
                (Some(c), Some(e)) => near(c, e, extent),
                _ => false,
            };
        if !fits {
            return Err(format!(
                "the result of job {job_id} is not framed on object `{}` from the job's eye",
                spec.object
            ));
        }
        Ok(())
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
    pub(super) fn cancel_on_worker(&mut self, job_id: u64) {
        if let Some(job) = self.jobs.get(&job_id)
            && let JobState::Running { worker, .. } = job.state
            && let Some(w) = self.workers.get_mut(&worker)
        {
            let cancel = pb::ServerMessage {
                kind: Some(pb::server_message::Kind::Cancel(pb::CancelJob { job_id })),
            };
            let _ = w.tx.send(Ok(cancel));
            w.stopping.insert(job_id, Instant::now());
        }
    }

    /// Jobs whose worker has shown no progress (taken them, or sent a preview) for
    /// [`Limits::job_progress`](super::Limits::job_progress) are taken back: stopped on
    /// that worker — whose slot stays taken until it answers, so a worker that hangs
    /// gets no more — and queued first for another.
    pub fn expire_stalled_jobs(&mut self) {
        self.expire_stalled_jobs_at(Instant::now());
    }

    /// [`expire_stalled_jobs`](Self::expire_stalled_jobs) as of `now`.
    pub(super) fn expire_stalled_jobs_at(&mut self, now: Instant) {
        let limit = self.limits.job_progress;
        let stalled: Vec<u64> = (self.jobs.iter())
            .filter(|(_, job)| match job.state {
                JobState::Running { progress, .. } => now.saturating_duration_since(progress) > limit,
                JobState::Queued(_) => false,
            })
            .map(|(&id, _)| id)
            .collect();
        for id in stalled {
            if self.take_back(id).is_some() {
                tracing::warn!(job = id, "no progress within {limit:?}: job taken back");
                self.counters.stalled += 1;
            }
        }
    }

    /// When no slot is free for `head`, the next job of `owner`: a worker to run it
    /// beside the jobs filling its slots, if it is needed now, small (at most
    /// [`EXPRESS_MAX_TEXELS`]), `owner` has nothing running, and the worker no other
    /// such job — so one client's long bakes hold another's small request neither for
    /// their length nor for a stop.
    fn express_worker(&self, owner: &Arc<str>, head: Priority) -> Option<u64> {
        let small = (self.jobs.get(&head.id))
            .is_some_and(|job| job.spec.size.saturating_mul(job.spec.size) <= EXPRESS_MAX_TEXELS);
        if head.predicted || !small || self.queue.running_of(owner) > 0 {
            return None;
        }
        (self.workers.iter())
            .filter(|(_, w)| !w.draining && w.running_beside() == 0)
            .min_by_key(|(_, w)| w.busy())
            .map(|(&id, _)| id)
    }

    /// When no slot is free for `head`, the next job of `owner`: if it is needed now
    /// and `owner` has nothing running, takes back a bake of the client with the most
    /// running — its latest, the least work lost; never one taken back before, so no
    /// job starves — so that one client's long bakes do not hold another's request for
    /// their whole length. The slot is lent at once (a bake checks for a stop every
    /// block of rays; see [`Worker::lent`](super::workers::Worker)), and the queue's
    /// order gives it to `owner`. Returns whether a slot was lent.
    fn preempt_for(&mut self, owner: &Arc<str>, head: Priority) -> bool {
        // (A slot already coming free — a job told to stop within `STOP_GRACE` — serves
        // it first; and a job taken back takes none back in turn, or two clients would
        // take one slot from each other for ever.)
        let now = Instant::now();
        let freeing = (self.workers.values())
            .flat_map(|w| w.stopping.values())
            .any(|&told| now.saturating_duration_since(told) < STOP_GRACE);
        let taken_back = self.jobs.get(&head.id).is_some_and(|job| job.preempted);
        if head.predicted || freeing || taken_back || self.queue.running_of(owner) > 0 {
            return false;
        }
        let victim = (self.jobs.iter())
            .filter_map(|(&id, job)| match job.state {
                JobState::Running { started, .. } if !job.preempted && job.owner != *owner => {
                    Some((self.queue.running_of(&job.owner), started, id))
                }
                _ => None,
            })
            .max();
        let Some((_, _, id)) = victim else {
            return false;
        };
        let Some(worker) = self.take_back(id) else {
            return false;
        };
        if let Some(job) = self.jobs.get_mut(&id) {
            job.preempted = true;
        }
        self.counters.preempted += 1;
        self.workers.get_mut(&worker).is_some_and(|w| w.lent.insert(id))
    }

    /// Takes running job `id` back from its worker: told to stop it (its slot stays
    /// taken until it answers), and queued first for the next free slot. Returns the
    /// worker it ran on, if it was running.
    fn take_back(&mut self, id: u64) -> Option<u64> {
        self.cancel_on_worker(id);
        let Some(JobState::Running { worker, .. }) = self.jobs.get(&id).map(|job| &job.state) else {
            return None;
        };
        let worker = *worker;
        if let Some(w) = self.workers.get_mut(&worker) {
            w.running.remove(&id);
        }
        self.requeue_first(id).then_some(worker)
    }

    /// Running job `id`, let go by its worker (taken back, or the worker gone), goes
    /// back to the queue first in its client's line. Returns whether it was there.
    pub(super) fn requeue_first(&mut self, id: u64) -> bool {
        let Some(job) = self.jobs.get_mut(&id) else {
            return false;
        };
        let priority = Priority {
            predicted: false,
            deadline_us: 0,
            id,
        };
        job.state = JobState::Queued(priority);
        // (Its next worker may hold the scene already: timed again.)
        job.loaded_scene = false;
        self.queue.stopped(&job.owner);
        self.queue.insert(&job.owner, priority);
        true
    }

    /// Requests waiting longer than [`Limits::job_timeout`](super::Limits::job_timeout) end with DEADLINE_EXCEEDED
    /// (each by its own arrival: one merged into an old job gets the whole time); a
    /// job nobody waits for any more then ends, stopped on its worker.
    pub fn expire_jobs(&mut self) {
        self.expire_jobs_at(Instant::now());
    }

    /// [`expire_jobs`](Self::expire_jobs) as of `now`: a test can name the instant
    /// instead of racing the clock.
    pub(super) fn expire_jobs_at(&mut self, now: Instant) {
        let timeout = self.limits.job_timeout;
        let expired: Vec<WaiterId> = self
            .waiters
            .iter()
            .filter(|(_, w)| now.saturating_duration_since(w.arrived) > timeout)
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
    pub(super) fn end_waiter(&mut self, waiter_id: &WaiterId, status: Status) -> bool {
        let Some(waiter) = self.waiters.remove(waiter_id) else {
            return false;
        };
        self.no_longer_waiting(&waiter.owner);
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
    pub(super) fn finish(&mut self, job_id: u64) {
        let Some(job) = self.jobs.remove(&job_id) else {
            return;
        };
        if let Some(ids) = self.by_subject.get_mut(&job.key.subject) {
            ids.retain(|&id| id != job_id);
            if ids.is_empty() {
                self.by_subject.remove(&job.key.subject);
            }
        }
        match job.state {
            JobState::Queued(p) => {
                self.queue.remove(&job.owner, &p);
            }
            JobState::Running { worker, .. } => {
                self.queue.stopped(&job.owner);
                if let Some(w) = self.workers.get_mut(&worker) {
                    w.running.remove(&job_id);
                }
            }
        }
        for waiter_id in job.waiters {
            if let Some(w) = self.waiters.remove(&waiter_id) {
                self.no_longer_waiting(&w.owner);
                self.latencies_push(w.arrived.elapsed().as_secs_f32() * 1e3);
            }
        }
    }

    /// One request of `owner` has ended.
    fn no_longer_waiting(&mut self, owner: &Arc<str>) {
        if let Some(count) = self.waiting_by_owner.get_mut(owner) {
            *count = count.saturating_sub(1);
            if *count == 0 {
                self.waiting_by_owner.remove(owner);
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
                Status::cancelled(relief_proto::WITHDRAWN),
            ) {
                withdrawn += 1;
                self.counters.withdrawn += 1;
            }
        }
        withdrawn
    }

    /// The job whose texture will serve `wanted`: a running one before a queued one
    /// (it finishes sooner), then the one nearest its eye, then the smallest. Only the
    /// subject's [`SUBJECT_SCAN`] newest jobs are looked through.
    pub(super) fn job_for(&self, wanted: &Wanted) -> Option<u64> {
        let rank = |job: &Job| {
            Some((
                matches!(job.state, JobState::Queued(_)),
                job.key.serves(wanted)?,
                job.key.size,
            ))
        };
        self.by_subject
            .get(&wanted.key.subject)?
            .iter()
            .rev()
            .take(SUBJECT_SCAN)
            .filter_map(|id| Some((*id, rank(self.jobs.get(id)?)?)))
            .min_by(|(_, a), (_, b)| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)))
            .map(|(id, _)| id)
    }
}
