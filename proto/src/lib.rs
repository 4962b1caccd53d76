//! Relief's gRPC protocol: the code generated from `relief/v1/relief.proto` (in
//! [`pb`]) and the checked conversions between wire messages and `relief-core` types
//! (in [`convert`]) — every message is validated here, where it enters a process — and
//! scene bundles ([`bundle`]), how scenes travel by content hash; and what the server
//! and the workers share besides: the bearer token ([`auth`]), endpoints
//! ([`connect`]) and the shutdown signal ([`shutdown`]).

pub mod auth;
pub mod bundle;
pub mod connect;
pub mod convert;
pub mod shutdown;

/// The generated messages, clients and servers of package `relief.v1`.
#[allow(clippy::all, missing_docs)]
pub mod pb {
    tonic::include_proto!("relief.v1");

    /// The encoded file descriptor set, for gRPC server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] = tonic::include_file_descriptor_set!("relief_descriptor");
}
