//! The counters and latency figures the server reports in `Impostors.Stats`.

use std::collections::{BTreeMap, VecDeque};

use relief_core::stats::percentile;
use relief_proto::pb;

use super::State;

/// Counters a person can read (see `Stats` in the protocol).
#[derive(Debug, Default, Clone)]
pub struct Counters {
    pub requests: u64,
    pub cache_hits: u64,
    pub merged: u64,
    /// Cache hits and merges served by a texture made for another eye.
    pub served_nearby: u64,
    pub withdrawn: u64,
    pub requeued: u64,
    /// Cancelled jobs their workers stopped before finishing.
    pub stopped: u64,
    /// Requests ended by [`Limits::job_timeout`](super::Limits::job_timeout).
    pub timed_out: u64,
    /// Results that came for jobs no longer wanted.
    pub discarded: u64,
    /// Workers dropped for answering for a job not leased to them, or with a texture
    /// that is not the job's.
    pub forged: u64,
    /// Scenes evicted from the store to make room for others.
    pub scenes_evicted: u64,
    /// Jobs taken back from a worker that showed no progress on them.
    pub stalled: u64,
    /// Jobs taken back from their worker for another client's needed-now request.
    pub preempted: u64,
    /// Predicted requests refused: they could not be ready when needed.
    pub shed: u64,
    /// Requests refused, by the gRPC code they were refused with (`tonic::Code as i32`).
    pub refused: BTreeMap<i32, u64>,
}

/// Upper bounds (ms) of the request latency histogram in [`pb::StatsReply`].
pub const LATENCY_BUCKETS_MS: [f32; 12] = [
    1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0,
];

pub(super) const LATENCY_SAMPLES: usize = 10_000;

/// Appends to a bounded window of recent samples.
pub(super) fn push_sample(samples: &mut VecDeque<f32>, value: f32) {
    if samples.len() == LATENCY_SAMPLES {
        samples.pop_front();
    }
    samples.push_back(value);
}

impl State {
    pub(super) fn latencies_push(&mut self, ms: f32) {
        push_sample(&mut self.latencies, ms);
        let bucket = LATENCY_BUCKETS_MS.partition_point(|&bound| bound < ms);
        self.latency_counts[bucket] += 1;
        self.latency_sum_ms += f64::from(ms);
    }

    /// Counts a request refused with `code`.
    pub fn count_refusal(&mut self, code: tonic::Code) {
        *self.counters.refused.entry(code as i32).or_default() += 1;
    }

    /// The request latency histogram since start: the counts per
    /// [`LATENCY_BUCKETS_MS`] bucket (one more: above the last bound) and their sum, ms.
    pub fn latency_histogram(&self) -> (&[u64], f64) {
        (&self.latency_counts, self.latency_sum_ms)
    }

    /// Records the time (µs) the server's code spent on one request or result.
    pub fn record_handling(&mut self, us: f32) {
        push_sample(&mut self.handling, us);
    }

    /// The counters as the protocol's `StatsReply`.
    pub fn stats(&self) -> pb::StatsReply {
        let samples = |samples: &VecDeque<f32>| samples.iter().map(|&s| f64::from(s)).collect::<Vec<f64>>();
        let (latencies, handling) = (samples(&self.latencies), samples(&self.handling));
        // (0 before any sample, as the protocol says.)
        let quantile_or_zero = |v: &[f64], p: f64| match percentile(v, p) {
            q if q.is_nan() => 0.0,
            q => q as f32,
        };
        let queued = |predicted: bool| self.queue.count(predicted) as u32;
        pb::StatsReply {
            queue_now: queued(false),
            queue_predicted: queued(true),
            jobs_in_flight: self.workers.values().map(|w| w.running.len() as u32).sum(),
            workers: self.workers.len() as u32,
            requests: self.counters.requests,
            cache_hits: self.counters.cache_hits,
            merged: self.counters.merged,
            served_nearby: self.counters.served_nearby,
            instance: self.instance,
            withdrawn: self.counters.withdrawn,
            requeued: self.counters.requeued,
            cache_bytes: self.cache_bytes as u64,
            latency_ms_p50: quantile_or_zero(&latencies, 0.5),
            latency_ms_p99: quantile_or_zero(&latencies, 0.99),
            handling_us_p50: quantile_or_zero(&handling, 0.5),
            handling_us_p99: quantile_or_zero(&handling, 0.99),
            jobs_stopped: self.counters.stopped,
            jobs_timed_out: self.counters.timed_out,
            latency_bucket_ms: LATENCY_BUCKETS_MS.to_vec(),
            latency_counts: self.latency_counts.to_vec(),
            worker_slots: self.workers.values().map(|w| w.slots as u32).sum(),
            worker_threads: self.workers.values().map(|w| w.threads).sum(),
            results_discarded: self.counters.discarded,
            workers_dropped_forged: self.counters.forged,
            scenes_evicted: self.counters.scenes_evicted,
            jobs_stalled: self.counters.stalled,
            jobs_preempted: self.counters.preempted,
            estimated_wait_ms: millis_or_zero(self.estimated_wait()),
            queue_wait_ms: millis_or_zero(self.queue_wait()),
            predictions_shed: self.counters.shed,
            scene_bytes: self.scene_bytes() as u64,
        }
    }
}

/// A wait in whole milliseconds (at most `u32::MAX`), 0 when there is none.
fn millis_or_zero(wait: Option<std::time::Duration>) -> u32 {
    wait.map_or(0, |wait| wait.as_millis().min(u128::from(u32::MAX)) as u32)
}
