//! Relief's server: the one address clients and workers need. The `relief-server`
//! binary (`src/main.rs`) serves this library over gRPC, with health checking and
//! reflection.
//!
//! # Brief overview
//!
//! The principal type is [`State`](state::State): every rule of the scheduler, as
//! plain data changed under one lock by methods that never wait, so each can be tested
//! without a network. [`Service`](service::Service) answers the three gRPC services
//! with it.
//!
//! ```
//! use std::time::Duration;
//! use relief_server::state::{Limits, State};
//!
//! let state = State::new(Limits {
//!     cache_bytes: 64 << 20,
//!     lease: Duration::from_secs(5),
//!     max_waiting: 1000,
//!     max_waiting_per_client: 100,
//!     scene_store_bytes: 256 << 20,
//!     job_progress: Duration::from_secs(30),
//!     job_timeout: Duration::from_secs(60),
//! });
//! let stats = state.stats();
//! assert_eq!((stats.workers, stats.requests), (0, 0));
//! ```
//!
//! - [`state`] — the scheduler and registries as plain data under one lock: scenes by
//!   content hash, the job queue (needed-now before predicted, nearest deadline first,
//!   identical requests merged, withdrawn ones cancelled), workers with leases (a
//!   vanished worker's jobs go back to the queue), the result cache bounded in bytes,
//!   and the counters.
//! - [`connections`] — accepting connections within bounds (how many open, how soon
//!   each must speak), backing off when out of descriptors.
//! - [`identity`] — who calls: each credential a client's or a worker's, and what it
//!   owns.
//! - [`service`] — the gRPC services (`Scenes`, `Impostors`, `Workers`) over it.
//! - [`metrics`] — the same counters for Prometheus (`--metrics-listen`).

pub mod connections;
pub mod identity;
pub mod metrics;
pub mod service;
pub mod state;
