//! `relief bench raytrace`: BVH build time and the primary-ray throughput of a bake, on
//! one thread and on all.

use anyhow::{Context, Result};
use clap::Args;
use glam::Vec3;
use serde::Serialize;

use relief_core::relief::DepthBits;
use relief_core::scene::SceneObject;
use relief_trace::bake;
use relief_trace::bake::trace_texels;
use relief_trace::bvh::Bvh;
use relief_trace::tracer::ObjectTracer;

use crate::{args, progress};
use relief_lab::timing::best_ms;

#[derive(Args)]
pub struct RaytraceArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Object to trace (default: the one with the most triangles).
    #[arg(long)]
    object: Option<String>,
    /// Which way the texels' rays go: parallel, or from the eye (as the client asks
    /// for open surfaces' textures).
    #[arg(long, value_enum, default_value_t = args::ProjectionArg::Orthographic)]
    projection: args::ProjectionArg,
    /// Bake size N: N² primary rays per run.
    #[arg(long, default_value = "256", value_parser = args::texture_size, allow_hyphen_values = true)]
    size: u32,
    /// Timed runs per measurement (best is reported), after one warm-up.
    #[arg(long, default_value = "5", value_parser = clap::value_parser!(u32).range(1..=1000))]
    runs: u32,
    /// Embree's rays per second on the same texture's rays (from
    /// `../shared/tools/embree_rays.py`, same machine, same run): prints the ratios.
    #[arg(long, value_parser = args::positive)]
    anchor_rays_per_s: Option<f32>,
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
    /// The bake's eye, for `relief bake --eye` when measuring the anchor on the same rays.
    eye: [f32; 3],
    bake_ms_1t: f64,
    bake_ms_mt: f64,
    rays_per_s_1t: f64,
    rays_per_s_mt: f64,
    /// The rays alone (no shading), all threads; `shade_ms` is the rest of the bake.
    trace_ms: f64,
    shade_ms: f64,
    trace_rays_per_s: f64,
    /// Texels the object covers (rays that hit).
    covered: usize,
    threads: usize,
    /// `rays_per_s_mt` and `trace_rays_per_s` over `--anchor-rays-per-s`.
    embree_ratio: Option<f64>,
    embree_ratio_trace: Option<f64>,
}

pub fn run(args: RaytraceArgs) -> Result<()> {
    let runs = args.runs as usize;
    let bar = progress::spinner("loading scene");
    let scene = crate::args::load_scene(&args.scene)?;
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
    let bvh_build_ms = best_ms(runs.min(3), || drop(Bvh::build(mesh)));
    let tracer = ObjectTracer::new(object);
    // A fixed, oblique view from three bounding radii away.
    let radius = object.local_bounds.extent().length() * 0.5;
    let eye = object.local_bounds.center() + Vec3::new(0.45, 0.35, 0.82).normalize() * radius * 3.0;
    let bake_once = || bake(&tracer, eye, args.size, DepthBits::Eight, args.projection.into()).map(drop);
    bake_once()?;
    bar.set_message("tracing, all threads");
    let bake_ms_mt = best_ms(runs, || drop(bake_once()));
    let trace_once = || trace_texels(&tracer, eye, args.size, args.projection.into());
    let covered = trace_once()?;
    let trace_ms = best_ms(runs, || drop(trace_once()));
    bar.set_message("tracing, one thread");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("creating a one-thread pool")?;
    let bake_ms_1t = one.install(|| best_ms(runs, || drop(bake_once())));
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
        eye: eye.to_array(),
        bake_ms_1t,
        bake_ms_mt,
        rays_per_s_1t: rays / (bake_ms_1t * 1e-3),
        rays_per_s_mt: rays / (bake_ms_mt * 1e-3),
        trace_ms,
        shade_ms: (bake_ms_mt - trace_ms).max(0.0),
        trace_rays_per_s: rays / (trace_ms * 1e-3),
        covered,
        threads: rayon::current_num_threads(),
        embree_ratio: args
            .anchor_rays_per_s
            .map(|anchor| rays / (bake_ms_mt * 1e-3) / anchor as f64),
        embree_ratio_trace: args
            .anchor_rays_per_s
            .map(|anchor| rays / (trace_ms * 1e-3) / anchor as f64),
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{}: {} triangles, BVH {:.1} ms ({} nodes, {:.1} B/triangle)\n\
             bake {}² from {},{},{}: {:.2} ms on 1 thread ({:.2} Mrays/s), {:.2} ms on {} threads ({:.2} Mrays/s)",
            report.object,
            report.triangles,
            report.bvh_build_ms,
            report.bvh_nodes,
            report.bytes_per_triangle,
            report.size,
            eye.x,
            eye.y,
            eye.z,
            report.bake_ms_1t,
            report.rays_per_s_1t / 1e6,
            report.bake_ms_mt,
            report.threads,
            report.rays_per_s_mt / 1e6
        );
        println!(
            "  of which tracing {:.2} ms ({:.2} Mrays/s, {} of {} texels covered), shading {:.2} ms",
            report.trace_ms,
            report.trace_rays_per_s / 1e6,
            report.covered,
            rays,
            report.shade_ms
        );
        if let (Some(bake), Some(trace)) = (report.embree_ratio, report.embree_ratio_trace) {
            println!("  against Embree: {bake:.2}× (bake), {trace:.2}× (tracing alone)");
        }
    }
    Ok(())
}
