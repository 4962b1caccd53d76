//! The server's metrics for Prometheus (`--metrics-listen`): at each scrape, a snapshot
//! of the same counters `Impostors.Stats` reads, under the `relief_server_` prefix —
//! queue depth by urgency, jobs in flight, workers and their slots, the request
//! latency histogram, the result cache, and what was refused, discarded or taken back.
//! The endpoint itself is [`relief_proto::metrics`].

use std::sync::Arc;

use prometheus_client::collector::Collector;
use prometheus_client::encoding::DescriptorEncoder;
use prometheus_client::metrics::MetricType::{Counter, Gauge};
use prometheus_client::registry::Registry;

use relief_proto::metrics::{encode_by, encode_histogram, encode_one};

use crate::service::Shared;
use crate::state::stats::LATENCY_BUCKETS_MS;

/// The registry the endpoint serves: this server's counters.
pub fn registry(shared: Arc<Shared>) -> Registry {
    let mut registry = Registry::with_prefix("relief_server");
    registry.register_collector(Box::new(ServerCollector(shared)));
    registry
}

/// Reads the server's state at each scrape.
struct ServerCollector(Arc<Shared>);

impl std::fmt::Debug for ServerCollector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ServerCollector")
    }
}

/// A gRPC code as a metric label: its name in the protocol, lower case.
fn code_label(code: i32) -> &'static str {
    use tonic::Code::*;
    match tonic::Code::from_i32(code) {
        Ok => "ok",
        Cancelled => "cancelled",
        Unknown => "unknown",
        InvalidArgument => "invalid_argument",
        DeadlineExceeded => "deadline_exceeded",
        NotFound => "not_found",
        AlreadyExists => "already_exists",
        PermissionDenied => "permission_denied",
        ResourceExhausted => "resource_exhausted",
        FailedPrecondition => "failed_precondition",
        Aborted => "aborted",
        OutOfRange => "out_of_range",
        Unimplemented => "unimplemented",
        Internal => "internal",
        Unavailable => "unavailable",
        DataLoss => "data_loss",
        Unauthenticated => "unauthenticated",
    }
}

impl Collector for ServerCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        // (One lock, the numbers copied out: encoding runs without it.)
        let (stats, latency_counts, latency_sum_ms, refused) = {
            let state = self.0.state();
            let (counts, sum) = state.latency_histogram();
            (
                state.stats(),
                counts.to_vec(),
                sum,
                state.counters.refused.clone(),
            )
        };
        let e = &mut encoder;
        encode_by(
            e,
            ("queue_depth", "Requests waiting for a worker, by urgency", Gauge),
            "urgency",
            &[
                ("now", stats.queue_now.into()),
                ("predicted", stats.queue_predicted.into()),
            ],
        )?;
        encode_one(
            e,
            "jobs_in_flight",
            "Jobs running on workers",
            Gauge,
            stats.jobs_in_flight.into(),
        )?;
        encode_one(e, "workers", "Workers registered", Gauge, stats.workers.into())?;
        encode_one(
            e,
            "worker_slots",
            "Jobs the registered workers take at once",
            Gauge,
            stats.worker_slots.into(),
        )?;
        encode_one(
            e,
            "worker_threads",
            "Baking threads of the registered workers",
            Gauge,
            stats.worker_threads.into(),
        )?;
        encode_one(
            e,
            "estimated_wait_milliseconds",
            "How long a job queued now would take to finish (0: not known yet)",
            Gauge,
            stats.estimated_wait_ms.into(),
        )?;
        encode_one(
            e,
            "queue_wait_milliseconds",
            "How long a job queued now would wait behind the others: the part of the estimated wait that is saturation",
            Gauge,
            stats.queue_wait_ms.into(),
        )?;
        encode_one(
            e,
            "cache_bytes",
            "Bytes of finished textures cached",
            Gauge,
            stats.cache_bytes,
        )?;
        encode_one(
            e,
            "scene_store_bytes",
            "Bytes of scene bundles stored",
            Gauge,
            stats.scene_bytes,
        )?;
        let bounds_s: Vec<f64> = LATENCY_BUCKETS_MS.iter().map(|&ms| f64::from(ms) / 1e3).collect();
        encode_histogram(
            e,
            "request_latency_seconds",
            "Requests from arrival to their final result or error (withdrawn ones not counted)",
            (&bounds_s, &latency_counts, latency_sum_ms / 1e3),
        )?;
        let counters = [
            ("requests", "Texture requests taken in", stats.requests),
            ("cache_hits", "Requests answered from the cache", stats.cache_hits),
            (
                "merged",
                "Requests that joined a job made for an earlier one",
                stats.merged,
            ),
            (
                "served_nearby",
                "Requests served (cached or merged) by a texture made for another eye within their reach",
                stats.served_nearby,
            ),
            ("withdrawn", "Requests their clients withdrew", stats.withdrawn),
            (
                "requeued",
                "Jobs queued again (their worker left or was dropped)",
                stats.requeued,
            ),
            (
                "jobs_stopped",
                "Cancelled jobs their workers stopped",
                stats.jobs_stopped,
            ),
            (
                "jobs_timed_out",
                "Requests ended by the job timeout",
                stats.jobs_timed_out,
            ),
            (
                "jobs_stalled",
                "Jobs taken back from a worker that showed no progress",
                stats.jobs_stalled,
            ),
            (
                "jobs_preempted",
                "Jobs taken back for another client's needed-now request",
                stats.jobs_preempted,
            ),
            (
                "results_discarded",
                "Results for jobs nobody wanted any more",
                stats.results_discarded,
            ),
            (
                "workers_dropped_forged",
                "Workers dropped for results not their job's",
                stats.workers_dropped_forged,
            ),
            (
                "scenes_evicted",
                "Scenes evicted from the store",
                stats.scenes_evicted,
            ),
            (
                "predictions_shed",
                "Predicted requests refused: they could not be ready when needed",
                stats.predictions_shed,
            ),
        ];
        for (name, help, value) in counters {
            encode_one(e, name, help, Counter, value)?;
        }
        let refused: Vec<(&str, u64)> = refused.iter().map(|(&code, &n)| (code_label(code), n)).collect();
        encode_by(
            e,
            (
                "requests_refused",
                "Requests refused, by the gRPC code they were refused with",
                Counter,
            ),
            "reason",
            &refused,
        )
    }
}
