//! `relief bench …`: benchmarks that print numbers.

use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use glam::Vec3;
use serde::Serialize;

use relief_core::relief::DepthBits;
use relief_core::scene::{Scene, SceneObject};
use relief_worker::bake;
use relief_worker::bvh::Bvh;
use relief_worker::tracer::ObjectTracer;

use crate::{args, progress};

#[derive(Subcommand)]
pub enum BenchCommand {
    /// BVH build time and primary-ray throughput of a bake, one thread and all threads.
    Raytrace(RaytraceArgs),
    /// Display time of every warp method against memcpy and a naive pre-warp.
    Warp(WarpArgs),
    /// Loopback RPC latency against a bare gRPC call, and impostor requests end to end.
    Rpc(RpcArgs),
}

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

#[derive(Args)]
pub struct WarpArgs {
    /// Built-in scene name, .toml scene file, or .obj file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Object whose relief texture is warped.
    #[arg(long, default_value = "knot")]
    object: String,
    /// Texture edge N (N² texels).
    #[arg(long, default_value = "256", value_parser = args::texture_size, allow_hyphen_values = true)]
    size: u32,
    /// Angle between the texture's eye and the displayed eye, degrees.
    #[arg(long, default_value = "5", allow_hyphen_values = true, value_parser = crate::args::finite)]
    angle: f32,
    /// Frame edge in pixels.
    #[arg(long, default_value = "512", value_parser = args::frame_edge)]
    frame_size: u32,
    /// Timed runs per measurement (the median is reported), after one warm-up.
    #[arg(long, default_value = "21", value_parser = clap::value_parser!(u32).range(1..=10000))]
    runs: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct RaytraceArgs {
    /// Built-in scene name, .toml scene file, or .obj file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Object to trace (default: the one with the most triangles).
    #[arg(long)]
    object: Option<String>,
    /// Bake size N: N² primary rays per run.
    #[arg(long, default_value = "256", value_parser = args::texture_size, allow_hyphen_values = true)]
    size: u32,
    /// Timed runs per measurement (best is reported), after one warm-up.
    #[arg(long, default_value = "5", value_parser = clap::value_parser!(u32).range(1..=1000))]
    runs: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// What `relief bench raytrace --json` prints.
#[derive(Serialize)]
struct RaytraceReport {
    object: String,
    triangles: usize,
    bvh_build_ms: f64,
    bvh_nodes: usize,
    /// BVH + mesh heap bytes per triangle.
    bytes_per_triangle: f64,
    size: u32,
    bake_ms_1t: f64,
    bake_ms_mt: f64,
    rays_per_s_1t: f64,
    rays_per_s_mt: f64,
    threads: usize,
}

pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Raytrace(args) => raytrace(args),
        BenchCommand::Warp(args) => warp(args),
        BenchCommand::Rpc(args) => rpc(args),
    }
}

/// Median wall time of `runs` calls of `f`, in milliseconds, after one warm-up call.
fn median_ms(runs: u32, mut f: impl FnMut()) -> f64 {
    median_ms_after(runs, &mut (), |_| {}, |_| f())
}

/// As [`median_ms`] for calls on `state`, running the untimed `setup` on it before
/// each call.
fn median_ms_after<S>(
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
    relief_client::stats::median(times)
}

/// One method's line of `relief bench warp --json`.
#[derive(Serialize)]
struct WarpTiming {
    /// Display into the frame's G-buffer: warp + reconstruction (+ texture mapping).
    ms: f64,
    texels_per_s: f64,
    /// `ms` over a memcpy of the texture's bytes.
    memcpy_ratio: f64,
    /// `ms` over the naive per-texel eq. 3-1/3-2 (no lookup table).
    naive_ratio: f64,
    /// Pre-warp alone (warp + hole filling in the source plane; table 8.1's quantity).
    #[serde(skip_serializing_if = "Option::is_none")]
    prewarp_ms: Option<f64>,
    /// The pre-warp split into the halves above and below the epipole on two threads.
    #[serde(skip_serializing_if = "Option::is_none")]
    prewarp_split_ms: Option<f64>,
    /// The texture mapping of the pre-warped image into the frame alone (the rest of
    /// `ms`).
    #[serde(skip_serializing_if = "Option::is_none")]
    map_ms: Option<f64>,
}

#[derive(Serialize)]
struct WarpReport {
    object: String,
    size: u32,
    texels: usize,
    angle_deg: f32,
    frame_size: u32,
    runs: u32,
    /// Copy of the texture's albedo, normal and depth bytes.
    memcpy_ms: f64,
    /// Eq. 3-1/3-2 per texel with the k's and divisions, no table.
    naive_ms: f64,
    /// The same with the lookup table (two additions, two multiplications).
    lut_ms: f64,
    methods: std::collections::BTreeMap<String, WarpTiming>,
    /// Table 8.1 as ratios: each pre-warp variant's `prewarp_ms` over interleaved's.
    table_8_1: std::collections::BTreeMap<String, f64>,
    /// Two interleaved pre-warps (of this texture) three ways: which way of using the
    /// cores is faster here.
    two_prewarps: TwoPrewarps,
    /// Pull–push reconstruction of a 1280×720 layer with one splat per 2×2 pixels.
    pullpush_1280x720_ms: f64,
    /// The same impostor seen from four times as far: the full texture against the
    /// pyramid level the resolution test picks (no texels the screen cannot show).
    multires: MultiRes,
}

/// Two pre-warps on the machine's threads, ms for both.
#[derive(Serialize)]
struct TwoPrewarps {
    /// Each whole on a thread of its own, at once.
    own_threads_ms: f64,
    /// Each split into its halves across the threads, one after the other.
    split_in_turn_ms: f64,
    /// Each split, both at once: what a frame does with its impostors.
    split_at_once_ms: f64,
}

#[derive(Serialize)]
struct MultiRes {
    full_ms: f64,
    level: usize,
    level_size: u32,
    level_ms: f64,
    /// `full_ms / level_ms`.
    saving: f64,
}

fn warp(args: WarpArgs) -> Result<()> {
    use relief_client::evaluate::Solo;
    use relief_client::gbuffer::GBuffer;
    use relief_client::impostor::Impostor;
    use relief_client::warp::params::WarpParams;
    use relief_client::warp::prewarp::{Variant, prewarp, prewarp_split};
    use relief_client::warp::sprite::Sprite;
    use relief_client::warp::{Method, display, draw, prepare};

    let bar = progress::spinner("baking");
    let scene = Scene::load(&args.scene)?;
    let solo = Solo::new(&scene, &args.object, 3.0)?;
    let impostor = Impostor::new(solo.bake(solo.eye(0.0), args.size, DepthBits::Eight)?);
    let camera = solo.camera(solo.eye(args.angle), args.frame_size)?;
    let params = WarpParams::new(&impostor.texture, camera.eye)
        .map_err(|e| anyhow::anyhow!("--angle {}: {e}", args.angle))?;
    let texture = &impostor.texture;
    let texels = texture.depth.len();
    bar.set_message("baselines");
    // Baselines, measured in the same run.
    let (mut albedo, mut normal, mut depth) = (
        texture.albedo.clone(),
        texture.normal.clone(),
        texture.depth.clone(),
    );
    let memcpy_ms = median_ms(args.runs, || {
        albedo.copy_from_slice(&texture.albedo);
        normal.copy_from_slice(&texture.normal);
        depth.copy_from_slice(&texture.depth);
        std::hint::black_box((&albedo, &normal, &depth));
    });
    let mut warped = vec![glam::Vec2::ZERO; texels];
    let c = texture.camera;
    let (w, empty, bits) = (c.width as usize, texture.depth_bits.empty(), texture.depth_bits);
    let naive_ms = median_ms(args.runs, || {
        let cc = c.origin - std::hint::black_box(camera.eye);
        for (k, out) in warped.iter_mut().enumerate() {
            let q = texture.depth[k];
            if q == empty {
                continue;
            }
            let d = c.depth_near + q as f32 / bits.max_level() as f32 * (c.depth_far - c.depth_near);
            let k1 = c.f.dot(c.b.cross(cc)) / c.a.dot(c.b.cross(cc));
            let k2 = c.f.dot(cc.cross(c.a)) / c.b.dot(cc.cross(c.a));
            let k3 = c.f.dot(c.a.cross(c.b)) / cc.dot(c.a.cross(c.b));
            let (u, v) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
            *out = glam::Vec2::new((u - k1 * d) / (1.0 + k3 * d), (v - k2 * d) / (1.0 + k3 * d));
        }
        std::hint::black_box(&warped);
    });
    let lut_ms = median_ms(args.runs, || {
        for (k, out) in warped.iter_mut().enumerate() {
            let q = texture.depth[k];
            if q != empty {
                *out = params.warp((k % w) as f32 + 0.5, (k / w) as f32 + 0.5, q as usize);
            }
        }
        std::hint::black_box(&warped);
    });
    let mut gbuffer = GBuffer::new(camera.width, camera.height);
    let source_camera = solo.camera(solo.eye(0.0), args.frame_size)?;
    display(Method::Interleaved, &impostor, 0, &source_camera, &mut gbuffer)?;
    let sprite = Sprite::capture(&gbuffer, 0);
    let mut methods = std::collections::BTreeMap::new();
    for method in Method::ALL {
        bar.set_message(method.name());
        let ms = median_ms_after(
            args.runs,
            &mut gbuffer,
            |g| g.clear(),
            |gbuffer| match (method, &sprite) {
                (Method::Sprite, Some(s)) => s.draw(gbuffer),
                (Method::Sprite, None) => {}
                _ => drop(display(method, &impostor, 0, &camera, gbuffer)),
            },
        );
        let variant = match method {
            Method::TwoPass1d => Some(Variant::OneD),
            Method::TwoPassAsym => Some(Variant::Asymmetric),
            Method::TwoPassComp => Some(Variant::Compensated),
            Method::Interleaved => Some(Variant::Interleaved),
            _ => None,
        };
        let prewarp_ms = variant.map(|v| {
            median_ms(args.runs, || {
                drop(std::hint::black_box(prewarp(&impostor, &params, v)))
            })
        });
        let prewarp_split_ms = (method == Method::Interleaved).then(|| {
            median_ms(args.runs, || {
                drop(std::hint::black_box(prewarp_split(
                    &impostor,
                    &params,
                    Variant::Interleaved,
                    None,
                )))
            })
        });
        let map_ms = (method == Method::Interleaved).then(|| {
            median_ms_after(
                args.runs,
                &mut (GBuffer::new(camera.width, camera.height), None),
                |(gbuffer, prepared)| {
                    gbuffer.clear();
                    *prepared = prepare(method, &impostor, &camera).ok();
                },
                |(gbuffer, prepared)| {
                    if let Some(prepared) = prepared.take() {
                        let _ = draw(prepared, &impostor, 0, &camera, gbuffer);
                    }
                },
            )
        });
        methods.insert(
            method.name(),
            WarpTiming {
                ms,
                texels_per_s: texels as f64 / (ms * 1e-3),
                memcpy_ratio: ms / memcpy_ms,
                naive_ratio: ms / naive_ms,
                prewarp_ms,
                prewarp_split_ms,
                map_ms,
            },
        );
    }
    bar.set_message("two pre-warps");
    let two_prewarps = {
        use std::hint::black_box;
        let whole = || prewarp(&impostor, &params, Variant::Interleaved);
        let split = || prewarp_split(&impostor, &params, Variant::Interleaved, None);
        TwoPrewarps {
            own_threads_ms: median_ms(args.runs, || drop(black_box(rayon::join(whole, whole)))),
            split_in_turn_ms: median_ms(args.runs, || drop(black_box((split(), split())))),
            split_at_once_ms: median_ms(args.runs, || drop(black_box(rayon::join(split, split)))),
        }
    };
    bar.set_message("pull-push 1280x720");
    let pullpush_1280x720_ms = {
        use relief_client::warp::pullpush::{Layer, Splat, Tolerance, fill};
        let mut sparse = Layer::new(1280, 720);
        for y in (0..720).step_by(2) {
            for x in (0..1280).step_by(2) {
                sparse.pixels[y * 1280 + x] = Splat {
                    depth: 5.0 + (x as f32 * 0.01).sin(),
                    albedo: [128; 3],
                    normal: [128, 128, 255],
                };
            }
        }
        median_ms_after(
            args.runs,
            &mut sparse.clone(),
            |layer| layer.pixels.copy_from_slice(&sparse.pixels),
            |layer| {
                fill(layer, 2, |l| Tolerance {
                    per_depth: 0.01 * (1 << l) as f32,
                    constant: 0.0,
                })
            },
        )
    };
    bar.set_message("multi-resolution");
    let multires = {
        use relief_client::pyramid::Pyramid;
        let far_eye = solo.scene.objects[0].bounds.center()
            + (solo.eye(args.angle) - solo.scene.objects[0].bounds.center()) * 4.0;
        let far = relief_core::camera::Camera {
            eye: far_eye,
            ..camera
        };
        let pyramid = Pyramid::new(impostor.texture.clone(), 16);
        let level = pyramid.level_for(&far, 1.0);
        let mut time = |imp: &Impostor| {
            median_ms_after(
                args.runs,
                &mut gbuffer,
                |g| g.clear(),
                |g| {
                    let _ = display(Method::Interleaved, imp, 0, &far, g);
                },
            )
        };
        let (full_ms, level_ms) = (time(&pyramid.levels[0]), time(&pyramid.levels[level]));
        MultiRes {
            full_ms,
            level,
            level_size: pyramid.levels[level].texture.camera.width,
            level_ms,
            saving: full_ms / level_ms,
        }
    };
    bar.finish_and_clear();
    let interleaved = methods
        .get("interleaved")
        .and_then(|t: &WarpTiming| t.prewarp_ms)
        .unwrap_or(f64::NAN);
    let table_8_1 = methods
        .iter()
        .filter_map(|(name, t)| t.prewarp_ms.map(|ms| (name.clone(), ms / interleaved)))
        .collect();
    let report = WarpReport {
        object: args.object,
        size: args.size,
        texels,
        angle_deg: args.angle,
        frame_size: args.frame_size,
        runs: args.runs,
        memcpy_ms,
        naive_ms,
        lut_ms,
        methods,
        table_8_1,
        two_prewarps,
        pullpush_1280x720_ms,
        multires,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} {}² ({} texels), {}° turn, {}² frame; memcpy {:.4} ms, naive eq. 3-1/3-2 {:.4} ms, with table {:.4} ms",
        report.object,
        report.size,
        report.texels,
        report.angle_deg,
        report.frame_size,
        memcpy_ms,
        naive_ms,
        lut_ms
    );
    println!(
        "pull-push 1280x720: {:.3} ms; multi-resolution at 4x the distance: full {:.3} ms, level {} ({}²) {:.3} ms ({:.1}x)",
        report.pullpush_1280x720_ms,
        report.multires.full_ms,
        report.multires.level,
        report.multires.level_size,
        report.multires.level_ms,
        report.multires.saving
    );
    let table: Vec<String> = report
        .table_8_1
        .iter()
        .map(|(k, v)| format!("{k} {v:.2}"))
        .collect();
    println!("table 8.1 (pre-warp time over interleaved): {}", table.join(", "));
    let two = &report.two_prewarps;
    println!(
        "two interleaved pre-warps: each on its own thread {:.3} ms, each split in turn {:.3} ms, both split at once {:.3} ms",
        two.own_threads_ms, two.split_in_turn_ms, two.split_at_once_ms
    );
    println!(
        "{:<18} {:>9} {:>11} {:>9} {:>9} {:>11} {:>11} {:>9}",
        "method", "ms", "Mtexels/s", "/memcpy", "/naive", "prewarp ms", "split ms", "map ms"
    );
    for (name, t) in &report.methods {
        let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
        println!(
            "{name:<18} {:>9.3} {:>11.1} {:>9.1} {:>9.1} {:>11} {:>11} {:>9}",
            t.ms,
            t.texels_per_s / 1e6,
            t.memcpy_ratio,
            t.naive_ratio,
            opt(t.prewarp_ms),
            opt(t.prewarp_split_ms),
            opt(t.map_ms)
        );
    }
    Ok(())
}

/// Best wall time of `runs` calls of `f`, in milliseconds, after one warm-up call.
fn best_ms(runs: u32, mut f: impl FnMut()) -> f64 {
    f();
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

fn raytrace(args: RaytraceArgs) -> Result<()> {
    let bar = progress::spinner("loading scene");
    let scene = Scene::load(&args.scene)?;
    let object: &SceneObject = match &args.object {
        Some(name) => scene.object(name)?,
        None => scene
            .objects
            .iter()
            .max_by_key(|o| o.mesh.triangle_count())
            .context("the scene has no objects")?,
    };
    bar.set_message("building BVH");
    let mesh = &object.mesh;
    let bvh_build_ms = best_ms(args.runs.min(3), || drop(Bvh::build(mesh)));
    let tracer = ObjectTracer::new(object);
    // A fixed, oblique view from three bounding radii away.
    let radius = object.bounds.extent().length() * 0.5;
    let eye = object.bounds.center() + Vec3::new(0.45, 0.35, 0.82).normalize() * radius * 3.0;
    let bake_once = || bake(&tracer, eye, args.size, DepthBits::Eight).map(drop);
    bake_once()?;
    bar.set_message("tracing, all threads");
    let bake_ms_mt = best_ms(args.runs, || drop(bake_once()));
    bar.set_message("tracing, one thread");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("creating a one-thread pool")?;
    let bake_ms_1t = one.install(|| best_ms(args.runs, || drop(bake_once())));
    bar.finish_and_clear();
    let rays = args.size as f64 * args.size as f64;
    let triangles = mesh.triangle_count();
    let report = RaytraceReport {
        object: object.name.clone(),
        triangles,
        bvh_build_ms,
        bvh_nodes: tracer.bvh.node_count(),
        bytes_per_triangle: (tracer.bvh.heap_bytes() + mesh.heap_bytes()) as f64 / triangles as f64,
        size: args.size,
        bake_ms_1t,
        bake_ms_mt,
        rays_per_s_1t: rays / (bake_ms_1t * 1e-3),
        rays_per_s_mt: rays / (bake_ms_mt * 1e-3),
        threads: rayon::current_num_threads(),
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{}: {} triangles, BVH {:.1} ms ({} nodes, {:.1} B/triangle)\n\
             bake {}²: {:.2} ms on 1 thread ({:.2} Mrays/s), {:.2} ms on {} threads ({:.2} Mrays/s)",
            report.object,
            report.triangles,
            report.bvh_build_ms,
            report.bvh_nodes,
            report.bytes_per_triangle,
            report.size,
            report.bake_ms_1t,
            report.rays_per_s_1t / 1e6,
            report.bake_ms_mt,
            report.threads,
            report.rays_per_s_mt / 1e6
        );
    }
    Ok(())
}

fn rpc(args: RpcArgs) -> Result<()> {
    use super::processes::{Children, connect_and_upload, start_server, start_workers};
    use relief_proto::convert::vec3_to_pb;
    use relief_proto::pb;

    // The processes' scene directories, removed at the end — after the processes, which
    // are declared later and so dropped (killed) first.
    let dir = relief_proto::bundle::private_scene_dir("relief-bench-rpc")?;
    let mut children = Children(Vec::new());
    let bar = progress::spinner("starting server and workers");
    let url = start_server(&mut children, &dir.path().join("server"))?;
    start_workers(&mut children, &url, args.workers, dir.path())?;
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
            remote
                .stats()
                .await
                .map_err(|e| anyhow::anyhow!(e.message().to_string()))?;
            stats.push(start.elapsed().as_secs_f64() * 1e6);
        }
        bar.set_message("impostor requests");
        let object = Scene::load("default")?.object(&args.object)?.bounds;
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
            };
            let start = Instant::now();
            let mut stream = remote
                .request(request)
                .await
                .map_err(|e| anyhow::anyhow!(e.message().to_string()))?;
            let mut bake_ms = 0;
            while let Some(result) = stream
                .message()
                .await
                .map_err(|e| anyhow::anyhow!(e.message().to_string()))?
            {
                bake_ms = result.bake_ms;
            }
            if k > 0 {
                latency.push(start.elapsed().as_secs_f64() * 1e3);
                bake.push(bake_ms as f64);
            }
        }
        use relief_client::stats::percentile;
        let overhead: Vec<f64> = latency.iter().zip(&bake).map(|(l, b)| l - b).collect();
        let server = remote
            .stats()
            .await
            .map_err(|e| anyhow::anyhow!(e.message().to_string()))?;
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
    drop(children);
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
