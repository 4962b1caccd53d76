//! `relief bench …`: benchmarks that print numbers, each measured against a baseline
//! in the same run (machines here are noisy: compare ratios, and runs, not one figure).
//!
//! - [`raytrace`] — BVH build and primary-ray throughput of a bake.
//! - [`reference`](mod@reference) — a reference frame through the top-level BVH against every object
//!   in turn.
//! - [`raster`] — the rasterizer drawing objects along a camera path, against shading.
//! - [`warp`] — every display method's time against memcpy and a naive pre-warp.
//! - [`replay`] — the pre-warps a flight kept, timed again each alone.
//! - [`rpc`] — loopback RPC latency against a bare gRPC call; requests end to end.

mod raster;
mod raytrace;
mod reference;
mod replay;
mod rpc;
mod warp;

use anyhow::Result;
use clap::Subcommand;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// BVH build time and primary-ray throughput of a bake, one thread and all threads.
    Raytrace(raytrace::RaytraceArgs),
    /// A reference frame through the top-level BVH, nearest object first, against
    /// tracing every object in turn.
    Reference(reference::ReferenceBenchArgs),
    /// The rasterizer drawing objects as geometry along the camera path, against the
    /// shading pass of the same frames.
    Raster(raster::RasterArgs),
    /// Display time of every warp method against memcpy and a naive pre-warp.
    Warp(warp::WarpArgs),
    /// The pre-warps a flight kept (`relief demo --warp-samples K`), timed again each
    /// alone, with their texture mappings: per object kind and projection.
    Replay(replay::ReplayArgs),
    /// Loopback RPC latency against a bare gRPC call, and impostor requests end to end.
    Rpc(rpc::RpcArgs),
}

pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Raytrace(args) => raytrace::run(args),
        BenchCommand::Reference(args) => reference::run(args),
        BenchCommand::Raster(args) => raster::run(args),
        BenchCommand::Warp(args) => warp::run(args),
        BenchCommand::Replay(args) => replay::run(args),
        BenchCommand::Rpc(args) => rpc::run(args),
    }
}
