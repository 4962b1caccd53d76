//! `relief bench rpc`: loopback RPC latency of a control-plane call against a bare gRPC
//! call on the same connection, and impostor requests end to end.

use std::time::Instant;

use anyhow::Result;
use clap::Args;
use glam::Vec3;
use serde::Serialize;

use relief_core::scene::Scene;
use relief_core::stats::percentile;
use relief_proto::convert::vec3_to_pb;
use relief_proto::pb;

use crate::processes::{LocalService, connect_and_upload};
use crate::{args, progress};

#[derive(Args)]
pub struct RpcArgs {
    /// Workers to start.
    #[arg(long, default_value = "2", value_parser = clap::value_parser!(u32).range(1..=64))]
    workers: u32,
    /// Control-plane calls timed (each kind).
    #[arg(long, default_value = "2000", value_parser = clap::value_parser!(u32).range(10..=1_000_000))]
    calls: u32,
    /// Impostor requests timed (each for a new eye, so nothing comes from the cache).
    #[arg(long, default_value = "30", value_parser = clap::value_parser!(u32).range(1..=10_000))]
    requests: u32,
    /// Texture edge of the requests.
    #[arg(long, default_value = "256", value_parser = args::texture_size, allow_hyphen_values = true)]
    size: u32,
    /// Object the requests are for.
    #[arg(long, default_value = "knot")]
    object: String,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// What `relief bench rpc --json` prints.
#[derive(Serialize)]
struct RpcReport {
    /// A bare gRPC call on the same server and connection: `grpc.health.v1` Check.
    echo_us_p50: f64,
    /// `Impostors.Stats`: a control-plane call through the server's state.
    stats_us_p50: f64,
    /// `stats_us_p50 / echo_us_p50`.
    control_ratio: f64,
    request_ms_p50: f64,
    request_ms_p99: f64,
    /// Time the workers spent baking, as they report it.
    bake_ms_p50: f64,
    /// Request latency minus bake time: queueing, transfer and the server.
    overhead_ms_p50: f64,
    /// Time the server's own code spends per message (request in, result on), as it
    /// reports it.
    server_handling_us_p50: f64,
    server_handling_us_p99: f64,
    requests: u32,
    size: u32,
    workers: u32,
}

pub fn run(args: RpcArgs) -> Result<()> {
    // The processes' scene directories, removed at the end — after the processes, which
    // are declared later and so dropped (killed) first.
    let dir = relief_proto::bundle::private_scene_dir("relief-bench-rpc")?;
    let bar = progress::spinner("starting server and workers");
    let service = LocalService::start(dir.path(), args.workers)?;
    let url = service.url.clone();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let report = runtime.block_on(async {
        let bundle = relief_proto::bundle::bundle_for("default")?;
        let (mut remote, hash) =
            connect_and_upload(&url, None, None, "bench", &bundle, Some(args.workers)).await?;
        let channel = tonic::transport::Endpoint::from_shared(url.clone())?
            .tcp_nodelay(true)
            .connect()
            .await?;
        let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
        bar.set_message("control-plane calls");
        let mut echo = Vec::new();
        let mut stats = Vec::new();
        for _ in 0..args.calls {
            let start = Instant::now();
            health
                .check(tonic_health::pb::HealthCheckRequest {
                    service: String::new(),
                })
                .await?;
            echo.push(start.elapsed().as_secs_f64() * 1e6);
            let start = Instant::now();
            remote.stats().await?;
            stats.push(start.elapsed().as_secs_f64() * 1e6);
        }
        bar.set_message("impostor requests");
        // (Eyes in the object's frame, as requests give them.)
        let object = Scene::load("default")?.object(&args.object)?.local_bounds;
        let (centre, radius) = (object.center(), object.extent().length() * 1.5);
        let mut latency = Vec::new();
        let mut bake = Vec::new();
        // One untimed request: the workers load the scene and build the BVH.
        for k in 0..=args.requests {
            let angle = k as f32 * 0.37;
            let eye = centre + Vec3::new(angle.sin(), 0.3, angle.cos()) * radius;
            let request = pb::ImpostorRequest {
                scene_hash: hash.to_string(),
                object: args.object.clone(),
                eye: Some(vec3_to_pb(eye)),
                size: args.size,
                depth_bits: 8,
                urgency: pb::Urgency::Now as i32,
                needed_in_ms: 0,
                client_id: "bench".into(),
                request_id: k as u64,
                progressive: false,
                // (What the client asks for.)
                projection: pb::SourceProjection::Perspective.into(),
                serve_within: 0.0,
                zstd_planes: true,
                zstd_delta_planes: true,
            };
            let start = Instant::now();
            let mut stream = remote.request(request).await?;
            let mut bake_ms = 0;
            while let Some(result) = stream.message().await? {
                bake_ms = result.bake_ms;
            }
            if k > 0 {
                latency.push(start.elapsed().as_secs_f64() * 1e3);
                bake.push(bake_ms as f64);
            }
        }
        let overhead: Vec<f64> = latency.iter().zip(&bake).map(|(l, b)| l - b).collect();
        let server = remote.stats().await?;
        let echo_us_p50 = percentile(&echo, 0.5);
        let stats_us_p50 = percentile(&stats, 0.5);
        Ok::<_, anyhow::Error>(RpcReport {
            echo_us_p50,
            stats_us_p50,
            control_ratio: stats_us_p50 / echo_us_p50,
            request_ms_p50: percentile(&latency, 0.5),
            request_ms_p99: percentile(&latency, 0.99),
            bake_ms_p50: percentile(&bake, 0.5),
            overhead_ms_p50: percentile(&overhead, 0.5),
            server_handling_us_p50: server.handling_us_p50 as f64,
            server_handling_us_p99: server.handling_us_p99 as f64,
            requests: args.requests,
            size: args.size,
            workers: args.workers,
        })
    })?;
    bar.finish_and_clear();
    drop(service);
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "loopback: bare gRPC call {:.0} µs p50, Stats {:.0} µs p50 ({:.2}x); {}² {} requests: {:.1} ms p50 / {:.1} ms p99 end to end, bake {:.1} ms, overhead {:.1} ms p50, server's own handling {:.0} µs p50 / {:.0} p99",
            report.echo_us_p50,
            report.stats_us_p50,
            report.control_ratio,
            report.size,
            args.object,
            report.request_ms_p50,
            report.request_ms_p99,
            report.bake_ms_p50,
            report.overhead_ms_p50,
            report.server_handling_us_p50,
            report.server_handling_us_p99
        );
    }
    Ok(())
}
