//! Workers: registration, heartbeats and leases (a silent worker's jobs go back to the
//! queue), draining before a worker stops.

use std::collections::{HashMap, HashSet};
use std::time::Instant;

use super::jobs::STOP_GRACE;
use super::{JobSender, State};

#[derive(Debug)]
pub(super) struct Worker {
    pub(super) name: String,
    /// The credential it registered with (see [`Caller`](crate::identity::Caller)):
    /// what it may read goes by it.
    pub(super) credential: std::sync::Arc<str>,
    pub(super) slots: usize,
    /// Threads each of its jobs bakes on (as it says; for Stats).
    pub(super) threads: u32,
    pub(super) running: HashSet<u64>,
    /// Jobs it was told to stop, and when, that it has not yet said it stopped (or
    /// finished): their slots stay taken, so a worker that hangs is not handed job
    /// after job.
    pub(super) stopping: HashMap<u64, Instant>,
    /// Of those, jobs taken back for another client's needed-now request, whose slot
    /// that request has at once, for [`STOP_GRACE`] (a bake stops within a block of
    /// rays: waiting for the worker to say so cost the request a round trip).
    pub(super) lent: HashSet<u64>,
    /// Jobs it was handed beside the ones filling its slots (see
    /// `State::express_worker`); those no longer running are dropped at the next.
    pub(super) beside: HashSet<u64>,
    /// It said it is stopping: no new jobs.
    pub(super) draining: bool,
    pub(super) tx: JobSender,
    pub(super) last_seen: Instant,
}

impl Worker {
    /// Slots taken: jobs running, and cancelled ones it has not answered for — but
    /// not a slot lent on within [`STOP_GRACE`] of the stop, nor a job running beside
    /// its slots.
    pub(super) fn busy(&self) -> usize {
        let now = Instant::now();
        let lent = (self.stopping.iter())
            .filter(|&(id, &told)| self.lent.contains(id) && now.saturating_duration_since(told) < STOP_GRACE)
            .count();
        self.running.len() + self.stopping.len() - lent - self.running_beside()
    }

    /// Jobs running beside its slots.
    pub(super) fn running_beside(&self) -> usize {
        self.beside.iter().filter(|id| self.running.contains(id)).count()
    }
}

impl State {
    /// Registers a worker of `credential`; returns its id.
    pub fn add_worker(
        &mut self,
        name: String,
        credential: std::sync::Arc<str>,
        slots: usize,
        threads: u32,
        tx: JobSender,
    ) -> u64 {
        let id = self.next();
        self.workers.insert(
            id,
            Worker {
                name,
                credential,
                slots,
                threads,
                running: HashSet::new(),
                stopping: HashMap::new(),
                lent: HashSet::new(),
                beside: HashSet::new(),
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

    /// Whether job `job_id` is the worker's to answer for: leased to it, or cancelled
    /// on it and not yet answered for.
    pub fn holds(&self, worker: u64, job_id: u64) -> bool {
        self.workers
            .get(&worker)
            .is_some_and(|w| w.running.contains(&job_id) || w.stopping.contains_key(&job_id))
    }

    /// The worker broke the protocol (answered for a job not its own, or with a
    /// texture that is not the job's): counted, logged, and dropped — its session ends
    /// with `status`, its jobs go back to the queue.
    pub fn forged(&mut self, worker: u64, status: tonic::Status) {
        self.counters.forged += 1;
        if let Some(w) = self.workers.get(&worker) {
            tracing::warn!(worker = %w.name, credential = %w.credential, "dropped: {}", status.message());
            let _ = w.tx.send(Err(status));
        }
        self.remove_worker(worker);
    }

    /// The worker is gone: its running jobs go back to the queue, first in line.
    pub fn remove_worker(&mut self, worker: u64) {
        let Some(w) = self.workers.remove(&worker) else {
            return;
        };
        tracing::info!(worker = %w.name, jobs = w.running.len(), "worker left; re-queueing its jobs");
        for id in w.running {
            if self.requeue_first(id) {
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
            w.lent.remove(&job_id);
        }
    }
}
