//! Admission under load: how long a new job would wait, and which predicted requests
//! are refused because they could not be ready when needed — on arrival (the wait
//! foreseen), or from the queue when a slot would start them past their use
//! ([`State::outlived`]).
//!
//! Without it, a server with more asked of it than its workers can bake queues
//! everything: at 64 clients on 2 workers every request waited seconds (p99 3.4 s) and
//! more than half of the clients' frames stalled. A predicted request is a guess made
//! ahead of need; one that would be finished long after the eye was due to need it is
//! work the workers cannot afford. Refused, it tells its client the server is
//! saturated (the wait it foresaw travels with the refusal, and in `Stats`), and the
//! client lets its textures live longer rather than ask for so many.

use std::time::{Duration, Instant};

use tonic::Status;

use super::State;
use super::queue::Priority;

/// The time a job takes is the median of this many of the latest: it follows a change
/// of texture size or load within a few jobs. (A job whose worker loaded the scene for
/// it is not counted: see `Job::loaded_scene`.)
pub const JOB_TIMES_KEPT: usize = 15;

/// A predicted request is refused when the foreseen wait exceeds the time until it is
/// needed by more than this: a texture a little late still serves (the client shows an
/// older one meanwhile), one far past its need is baking for nothing. (At 500 ms one
/// client at a 250 ms round trip had its own bursts refused and went stale 2–3× as
/// often; see docs/load-test.md.)
pub const SHED_SLACK: Duration = Duration::from_millis(1500);

/// A prediction is refused only while the wait has stayed long, as a mean over about
/// this long (each admission folding the wait in with weight `1 − e^(−Δt/τ)`): one
/// client's burst of requests (a flight's start, a turn) fills the queue for a moment;
/// overload from many clients stays.
pub const SATURATION_TIME_CONSTANT: Duration = Duration::from_secs(2);

impl State {
    /// Counts the time a finished job held its slot: from its dispatch (`started`) to
    /// its final texture.
    pub(super) fn job_took(&mut self, started: Instant) {
        if self.job_times.len() == JOB_TIMES_KEPT {
            self.job_times.pop_front();
        }
        self.job_times.push_back(started.elapsed().as_secs_f64());
    }

    /// The time a job takes: the median of the latest ([`JOB_TIMES_KEPT`]).
    fn job_time(&self) -> Option<f64> {
        let mut times: Vec<f64> = self.job_times.iter().copied().collect();
        times.sort_by(f64::total_cmp);
        times.get(times.len() / 2).copied()
    }

    /// How long a job queued now would take to finish: the jobs queued and running
    /// shared over the workers' slots, each taking the median time, then its own.
    /// `None` before any job has finished, or without a worker.
    pub fn estimated_wait(&self) -> Option<Duration> {
        let (job_time, slots, backlog) = self.backlog()?;
        Some(Duration::from_secs_f64(
            job_time * (backlog as f64 / slots as f64 + 1.0),
        ))
    }

    /// How long a job queued now would wait for a slot: none while one is free, else the
    /// jobs ahead of it past the slots, shared over them, each taking the median time.
    /// The server's saturation, apart from a job's own time — which, with workers a
    /// round trip of 100 ms away, never fell below the clients' threshold of room
    /// (`LOAD_LOW_WAIT`), and held their tolerance at its most for whole flights.
    /// `None` before any job has finished, or without a worker.
    pub fn queue_wait(&self) -> Option<Duration> {
        let (job_time, slots, backlog) = self.backlog()?;
        let ahead = (backlog + 1).saturating_sub(slots);
        Some(Duration::from_secs_f64(job_time * ahead as f64 / slots as f64))
    }

    /// The median job time, the workers' slots (at least one) and the jobs queued and
    /// running; `None` before any job has finished, or without a slot.
    fn backlog(&self) -> Option<(f64, usize, usize)> {
        let job_time = self.job_time()?;
        let slots: usize = self.workers.values().map(|w| w.slots).sum();
        if slots == 0 {
            return None;
        }
        let running: usize = self.workers.values().map(|w| w.running.len()).sum();
        Some((
            job_time,
            slots,
            self.queue.count(false) + self.queue.count(true) + running,
        ))
    }

    /// Folds the wait foreseen now into its mean over time (see
    /// [`SATURATION_TIME_CONSTANT`]); called at each admission.
    pub(super) fn track_wait(&mut self) {
        let now = Instant::now();
        let wait = self.estimated_wait().map_or(0.0, |w| w.as_secs_f64());
        self.mean_wait_s = match self.mean_wait_at {
            None => wait,
            Some(at) => {
                let dt = now.duration_since(at).as_secs_f64();
                let weight = 1.0 - (-dt / SATURATION_TIME_CONSTANT.as_secs_f64()).exp();
                self.mean_wait_s + weight * (wait - self.mean_wait_s)
            }
        };
        self.mean_wait_at = Some(now);
    }

    /// Whether a new job for a request needed in `in_ms` should be refused: the wait
    /// it would have, when both it and the mean wait of late are too long.
    pub(super) fn too_late(&self, in_ms: u64) -> Option<Duration> {
        let wait = self.estimated_wait()?;
        let limit = Duration::from_millis(in_ms) + SHED_SLACK;
        (wait > limit && Duration::from_secs_f64(self.mean_wait_s) > limit).then_some(wait)
    }

    /// How late a queued predicted job would start, if it has outlived its use: a slot
    /// free for it now would start it more than [`SHED_SLACK`] after the latest need
    /// of its requests. (Admitted in time, a prediction can still wait behind the
    /// queue until then: at 64 clients on two cores 12–13 % of predictions came late,
    /// the latest 4.2–4.4 s late — work the workers baked for nothing while timely
    /// requests waited.) Unlike admission, which weighs when a new job would finish,
    /// this weighs when it would start: a job past its use at its start is past it.
    pub(super) fn outlived(&self, queued: &Priority, now: Instant) -> Option<Duration> {
        let need = self.jobs.get(&queued.id)?.latest_need_us;
        let late = now
            .saturating_duration_since(self.epoch)
            .saturating_sub(Duration::from_micros(need));
        (queued.predicted && late > SHED_SLACK).then_some(late)
    }

    /// Ends queued job `job_id`, which [outlived](State::outlived) its use, refusing
    /// each of its requests as [`saturated`] (`late` past its need).
    pub(super) fn shed_queued(&mut self, job_id: u64, late: Duration) {
        let waiters: Vec<_> = self
            .jobs
            .get(&job_id)
            .map(|job| job.waiters.iter().cloned().collect())
            .unwrap_or_default();
        let refusal = saturated(
            format!(
                "saturated: the texture was needed {} ms ago and no worker has started it",
                late.as_millis()
            ),
            late,
        );
        for waiter in waiters {
            if self.end_waiter(&waiter, refusal.clone()) {
                self.counters.shed += 1;
                // (Refused as at admission, so counted as such too.)
                self.count_refusal(tonic::Code::ResourceExhausted);
            }
        }
        // (Gone with its last request; ended here too should it have had none, so
        // that the queue moves on.)
        self.finish(job_id);
    }
}

/// The refusal of a prediction the server cannot make in time: RESOURCE_EXHAUSTED with
/// `message`, and the wait it foresaw in the metadata the client reads
/// ([`relief_proto::SATURATED_METADATA`]).
pub(super) fn saturated(message: String, wait: Duration) -> Status {
    let mut refusal = Status::resource_exhausted(message);
    let ms = wait.as_millis().min(u128::from(u32::MAX));
    if let Ok(value) = ms.to_string().parse() {
        refusal
            .metadata_mut()
            .insert(relief_proto::SATURATED_METADATA, value);
    }
    refusal
}
