//! `relief bench …`: benchmarks that print numbers, each measured against a baseline
//! in the same run (machines here are noisy: compare ratios, and runs, not one figure).
//!
//! - [`raytrace`] — BVH build and primary-ray throughput of a bake.
//! - [`warp`] — every display method's time against memcpy and a naive pre-warp.
//! - [`rpc`] — loopback RPC latency against a bare gRPC call; requests end to end.

mod raytrace;
mod rpc;
mod warp;

use std::time::Instant;

use anyhow::Result;
use clap::Subcommand;

use relief_core::stats::median;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// BVH build time and primary-ray throughput of a bake, one thread and all threads.
    Raytrace(raytrace::RaytraceArgs),
    /// Display time of every warp method against memcpy and a naive pre-warp.
    Warp(warp::WarpArgs),
    /// Loopback RPC latency against a bare gRPC call, and impostor requests end to end.
    Rpc(rpc::RpcArgs),
}

pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Raytrace(args) => raytrace::run(args),
        BenchCommand::Warp(args) => warp::run(args),
        BenchCommand::Rpc(args) => rpc::run(args),
    }
}

/// Median wall time of `runs` calls of `f`, in milliseconds, after one warm-up call.
pub(super) fn median_ms(runs: u32, mut f: impl FnMut()) -> f64 {
    median_ms_after(runs, &mut (), |_| {}, |_| f())
}

/// As [`median_ms`] for calls on `state`, running the untimed `setup` on it before
/// each call.
pub(super) fn median_ms_after<S>(
    runs: u32,
    state: &mut S,
    mut setup: impl FnMut(&mut S),
    mut f: impl FnMut(&mut S),
) -> f64 {
    setup(state);
    f(state);
    let times: Vec<f64> = (0..runs)
        .map(|_| {
            setup(state);
            let start = Instant::now();
            f(state);
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    median(times)
}

/// Best wall time of `runs` calls of `f`, in milliseconds, after one warm-up call.
pub(super) fn best_ms(runs: u32, mut f: impl FnMut()) -> f64 {
    f();
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}
