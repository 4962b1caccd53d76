//! Relief's gRPC protocol: the code generated from `relief/v1/relief.proto` (in
//! [`pb`]) and the checked conversions between wire messages and `relief-core` types
//! (in [`convert`]) — every message is validated here, where it enters a process — and
//! scene bundles ([`bundle`]), how scenes travel by content hash; and what the server
//! and the workers share besides: the bearer token ([`auth`]), endpoints
//! ([`connect`]), the sizes of what crosses the wire ([`limits`]), textures' planes
//! compressed once ([`planes`]), the metrics endpoint ([`metrics`]) and the shutdown
//! signal ([`shutdown`]).
//!
//! # Brief overview
//!
//! The principal types are the messages of [`pb`] (`ImpostorRequest`, `Job`,
//! `ReliefTexture`, …), documented in the `.proto` file. Nothing reads a field of one
//! directly: [`convert`] turns each into a checked core type, and a bad field becomes
//! `INVALID_ARGUMENT` naming it. A [`Bundle`](bundle::Bundle) is a scene with every file
//! it needs, under one content hash.
//!
//! ```
//! use relief_proto::convert::{vec3_from_pb, vec3_to_pb};
//! use relief_proto::pb;
//!
//! let eye = vec3_from_pb("eye", Some(&vec3_to_pb(glam::Vec3::new(1.0, 2.0, 3.0))))?;
//! assert_eq!(eye, glam::Vec3::new(1.0, 2.0, 3.0));
//! let bad = vec3_from_pb("eye", Some(&pb::Vec3 { x: f32::NAN, y: 0.0, z: 0.0 })).unwrap_err();
//! assert_eq!(bad.code(), tonic::Code::InvalidArgument);
//! assert!(bad.message().contains("eye"));
//! # Ok::<(), tonic::Status>(())
//! ```

pub mod auth;
pub mod bundle;
pub mod connect;
pub mod convert;
pub mod limits;
pub mod metrics;
pub mod planes;
pub mod shutdown;

/// The message of the `CANCELLED` status that ends a withdrawn request's result
/// stream: an answer from the server, where a `CANCELLED` without it is a connection
/// that broke (a client tells the two apart by it).
pub const WITHDRAWN: &str = "withdrawn";

/// The gRPC metadata key on a `RESOURCE_EXHAUSTED` refusal of a predicted request the
/// server could not make in time, milliseconds: refused on arrival, the wait it
/// foresaw; refused from its queue, how late past its need it would have started. A
/// client takes it as "saturated", as it does a long `StatsReply.queue_wait_ms`.
pub const SATURATED_METADATA: &str = "relief-saturated-wait-ms";

/// The generated messages, clients and servers of package `relief.v1`.
#[allow(clippy::all, missing_docs)]
pub mod pb {
    tonic::include_proto!("relief.v1");

    /// The encoded file descriptor set, for gRPC server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] = tonic::include_file_descriptor_set!("relief_descriptor");
}
