//! Relief's server: the one address clients and workers need.
//!
//! - [`state`] — the scheduler and registries as plain data under one lock: scenes by
//!   content hash, the job queue (needed-now before predicted, nearest deadline first,
//!   identical requests merged, withdrawn ones cancelled), workers with leases (a
//!   vanished worker's jobs go back to the queue), the result cache bounded in bytes,
//!   and the counters.
//! - [`service`] — the gRPC services (`Scenes`, `Impostors`, `Workers`) over it.

pub mod service;
pub mod state;
