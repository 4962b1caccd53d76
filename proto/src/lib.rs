//! Relief's gRPC protocol: the `.proto` files, their generated code and the checked
//! conversions between wire messages and `relief-core` types.
//!
//! Nothing lives here yet: the protocol arrives with the distributed-impostors work
//! (server, workers, client over gRPC). See `ARCHITECTURE.md`.
