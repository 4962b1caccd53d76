//! The worker's metrics for Prometheus (`--metrics-listen`), under the
//! `relief_worker_` prefix: bakes by how they ended and how long each took, rays cast
//! (one per texel: their rate is the worker's rays/s), jobs running, and whether it is
//! registered with its server. The endpoint itself is [`relief_proto::metrics`].

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

/// The bake time histogram's first bound, seconds: a 32² preview takes a few ms …
const BAKE_SECONDS_FIRST_BOUND: f64 = 0.005;
/// … and its bounds double this many times: up to 82 s, past a 2048² bake of a
/// million triangles on a busy host.
const BAKE_SECONDS_BUCKETS: u16 = 15;

/// How a bake ended, as the `outcome` label.
pub type Outcome = [(&'static str, &'static str); 1];

/// What the worker counts; cheap to clone (each metric is shared).
#[derive(Clone)]
pub struct WorkerMetrics {
    pub bakes: Family<Outcome, Counter>,
    pub bake_seconds: Histogram,
    pub rays: Counter,
    pub jobs_running: Gauge,
    pub registered: Gauge,
}

impl WorkerMetrics {
    /// The metrics, and the registry that serves them.
    pub fn new() -> (WorkerMetrics, Registry) {
        let metrics = WorkerMetrics {
            bakes: Family::default(),
            bake_seconds: Histogram::new(exponential_buckets(
                BAKE_SECONDS_FIRST_BOUND,
                2.0,
                BAKE_SECONDS_BUCKETS,
            )),
            rays: Counter::default(),
            jobs_running: Gauge::default(),
            registered: Gauge::default(),
        };
        let mut registry = Registry::with_prefix("relief_worker");
        registry.register(
            "bakes",
            "Textures baked, by how the bake ended",
            metrics.bakes.clone(),
        );
        registry.register(
            "bake_seconds",
            "Time to bake one texture (a preview or a final one)",
            metrics.bake_seconds.clone(),
        );
        registry.register("rays", "Rays cast, one per texel baked", metrics.rays.clone());
        registry.register(
            "jobs_running",
            "Jobs being baked now",
            metrics.jobs_running.clone(),
        );
        registry.register(
            "registered",
            "1 while registered with the server, else 0",
            metrics.registered.clone(),
        );
        (metrics, registry)
    }

    /// Counts a bake that ended `outcome` ("finished", "stopped" or "failed").
    pub fn bake_ended(&self, outcome: &'static str) {
        self.bakes.get_or_create(&[("outcome", outcome)]).inc();
    }
}
