//! Relief's server: scene registry, priority scheduler, worker registry with leases, and
//! the result cache.
//!
//! Nothing lives here yet: the server arrives with the distributed-impostors work. See
//! `ARCHITECTURE.md`.
