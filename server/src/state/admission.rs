//! Admission under load: how long a new job would wait, and which predicted requests
//! are refused because they could not be ready when needed.
//!
//! Without it, a server with more asked of it than its workers can bake queues
//! everything: at 64 clients on 2 workers every request waited seconds (p99 3.4 s) and
//! more than half of the clients' frames stalled. A predicted request is a guess made
//! ahead of need; one that would be finished long after the eye was due to need it is
//! work the workers cannot afford. Refused, it tells its client the server is
//! saturated (the wait it foresaw travels with the refusal, and in `Stats`), and the
//! client lets its textures live longer rather than ask for so many.

use std::time::{Duration, Instant};

use super::State;

/// The weight of the newest job in the running mean of the time a job takes: about
/// the last five jobs count, so the estimate follows a change of texture size or of
/// load within seconds.
pub const JOB_TIME_WEIGHT: f64 = 0.2;

/// A predicted request is refused when the foreseen wait exceeds the time until it is
/// needed by more than this: a texture a little late still serves (the client shows an
/// older one meanwhile), one far past its need is baking for nothing.
pub const SHED_SLACK: Duration = Duration::from_millis(500);

impl State {
    /// Folds the time a finished job took (its dispatch to its final texture) into the
    /// running mean.
    pub(super) fn job_took(&mut self, started: Instant) {
        let took = started.elapsed().as_secs_f64();
        self.job_time_s = Some(match self.job_time_s {
            None => took,
            Some(mean) => mean + JOB_TIME_WEIGHT * (took - mean),
        });
    }

    /// How long a job queued now would take to finish: the jobs queued and running
    /// shared over the workers' slots, each taking the running mean, then its own.
    /// `None` before any job has finished, or without a worker.
    pub fn estimated_wait(&self) -> Option<Duration> {
        let job_time = self.job_time_s?;
        let slots: usize = self.workers.values().map(|w| w.slots).sum();
        if slots == 0 {
            return None;
        }
        let running: usize = self.workers.values().map(|w| w.running.len()).sum();
        let backlog = self.queue.count(false) + self.queue.count(true) + running;
        let rounds = backlog as f64 / slots as f64 + 1.0;
        Some(Duration::from_secs_f64(job_time * rounds))
    }

    /// Whether a new job for a request needed in `in_ms` should be refused: the wait
    /// it would have, if too long.
    pub(super) fn too_late(&self, in_ms: u64) -> Option<Duration> {
        let wait = self.estimated_wait()?;
        (wait > Duration::from_millis(in_ms) + SHED_SLACK).then_some(wait)
    }
}
