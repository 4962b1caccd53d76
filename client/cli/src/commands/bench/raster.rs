//! `relief bench raster`: the software rasterizer drawing objects as geometry along a
//! scene's camera path, against the frame's shading pass over the same pixels (the
//! one full-frame pass every frame pays).

use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use serde::Serialize;

use relief_client::manager::Manager;
use relief_core::camera::Camera;
use relief_core::scene::SceneObject;
use relief_render::gbuffer::{GBuffer, SurfaceDigest};
use relief_render::geometry::near_plane;
use relief_render::raster::rasterize;

use crate::{args, progress};

/// More objects than this are counted in the text, not named: a large scene has
/// hundreds.
const NAMED_OBJECTS: usize = 8;

#[derive(Args)]
pub struct RasterArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Objects to draw, by name, comma-separated (default: every object: the frame the
    /// demo compares impostors with).
    #[arg(long, value_delimiter = ',')]
    objects: Vec<String>,
    /// Of those, only the ones a client draws as geometry whatever textures it holds,
    /// frame by frame (`Manager::always_geometry`): the least geometry an impostor frame
    /// draws (objects standing in for textures not yet valid, and warps refused, add
    /// to it).
    #[arg(long)]
    as_client: bool,
    /// Draw every K-th frame of the camera path.
    #[arg(long, default_value = "10", value_parser = clap::value_parser!(u32).range(1..))]
    every: u32,
    /// Frame size WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360", value_parser = args::frame_size)]
    size: (u32, u32),
    /// Timed sweeps of the path (best is reported), after one warm-up.
    #[arg(long, default_value = "5", value_parser = clap::value_parser!(u32).range(1..=1000))]
    runs: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// What `relief bench raster --json` prints.
#[derive(Serialize)]
struct RasterReport {
    scene: String,
    /// The objects chosen (with `--as-client`, each frame draws those of them it
    /// would as geometry).
    objects: Vec<String>,
    /// Only those drawn as geometry whatever textures are held (`--as-client`).
    as_client: bool,
    /// Triangles of the objects in view (those the rasterizer sets up), per frame on
    /// average.
    triangles_per_frame: f64,
    width: u32,
    height: u32,
    /// Path frames drawn per sweep.
    frames: usize,
    /// Pixels the objects cover, per frame on average.
    covered_px: f64,
    /// Clearing the buffer and rasterizing the objects, per frame (all threads).
    raster_ms: f64,
    /// The shading pass of the same frames, per frame (all threads).
    shade_ms: f64,
    /// `raster_ms / shade_ms`.
    raster_to_shade: f64,
    /// `raster_ms` per triangle, nanoseconds.
    ns_per_triangle: f64,
    threads: usize,
    /// The digest of every frame's buffer as rasterized ([`SurfaceDigest`]), in the
    /// untimed first sweep: equal between two builds (or thread counts), the same
    /// images.
    gbuffer_digest: String,
}

pub fn run(args: RasterArgs) -> Result<()> {
    let bar = progress::spinner("loading scene");
    let scene = args::load_scene(&args.scene)?;
    let objects: Vec<(u32, &SceneObject)> = if args.objects.is_empty() {
        (scene.objects.iter().enumerate())
            .map(|(k, o)| (k as u32, o))
            .collect()
    } else {
        let mut chosen: Vec<(u32, &SceneObject)> = Vec::new();
        for name in &args.objects {
            let object = scene.object(name).context("--objects")?;
            // (Named twice, drawn once.)
            if !chosen.iter().any(|(_, o)| std::ptr::eq(*o, object)) {
                let k = scene.objects.iter().position(|o| std::ptr::eq(o, object));
                chosen.extend(k.map(|k| (k as u32, object)));
            }
        }
        chosen
    };
    let (width, height) = args.size;
    let cameras: Vec<Camera> = (0..scene.path.frame_count())
        .step_by(args.every as usize)
        .filter_map(|frame| scene.path.pose(frame))
        .map(|pose| pose.camera(scene.fov_y_degrees, width, height))
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow!("the camera path: {e}"))?;
    if cameras.is_empty() {
        bail!("the scene {:?} has no camera path to draw along", scene.name);
    }
    // What each frame draws: the chosen objects, or those of them drawn as geometry
    // from its eye.
    let drawn: Vec<Vec<(u32, &SceneObject)>> = (cameras.iter())
        .map(|camera| {
            (objects.iter().copied())
                .filter(|(_, o)| !args.as_client || Manager::always_geometry(o, camera))
                .collect()
        })
        .collect();
    let near = near_plane(&scene);
    // One buffer, as a client draws into: each frame rasterized, then shaded, each
    // timed; a sweep's sums, best of the runs.
    let mut gbuffer = GBuffer::new(width, height);
    bar.set_message("rasterizing and shading");
    let mut sweep = |mut digest: Option<&mut SurfaceDigest>| {
        let (mut raster, mut shade, mut covered) = (Duration::ZERO, Duration::ZERO, 0);
        for (camera, objects) in cameras.iter().zip(&drawn) {
            let start = Instant::now();
            gbuffer.clear();
            rasterize(objects, camera, near, &mut gbuffer);
            let rasterized = Instant::now();
            drop(gbuffer.shade(&scene, camera));
            (raster, shade) = (raster + (rasterized - start), shade + rasterized.elapsed());
            covered += gbuffer.covered();
            if let Some(digest) = digest.as_deref_mut() {
                digest.add(&gbuffer);
            }
        }
        (raster.as_secs_f64() * 1e3, shade.as_secs_f64() * 1e3, covered)
    };
    let mut digest = SurfaceDigest::new();
    sweep(Some(&mut digest));
    let (mut raster_ms, mut shade_ms, mut covered) = (f64::INFINITY, f64::INFINITY, 0);
    for _ in 0..args.runs {
        let (raster, shade, seen) = sweep(None);
        (raster_ms, shade_ms, covered) = (raster_ms.min(raster), shade_ms.min(shade), seen);
    }
    bar.finish_and_clear();
    let frames = cameras.len() as f64;
    // (Only the objects in view: the rasterizer sets up no other's triangles.)
    let triangles: usize = (cameras.iter().zip(&drawn))
        .flat_map(|(camera, objects)| {
            (objects.iter())
                .filter(|(_, o)| o.local_camera(camera).may_see(&o.local_bounds))
                .map(|(_, o)| o.mesh.triangle_count())
        })
        .sum();
    let (raster_ms, shade_ms) = (raster_ms / frames, shade_ms / frames);
    let report = RasterReport {
        scene: scene.name.clone(),
        objects: objects.iter().map(|(_, o)| o.name.clone()).collect(),
        as_client: args.as_client,
        triangles_per_frame: triangles as f64 / frames,
        width,
        height,
        frames: cameras.len(),
        covered_px: covered as f64 / frames,
        raster_ms,
        shade_ms,
        raster_to_shade: raster_ms / shade_ms,
        ns_per_triangle: raster_ms * 1e6 * frames / triangles.max(1) as f64,
        threads: rayon::current_num_threads(),
        gbuffer_digest: digest.finish().to_string(),
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        let objects = match report.objects.len() {
            n if n > NAMED_OBJECTS => format!("{n} objects"),
            _ => report.objects.join(", "),
        };
        println!(
            "{}: {}{}, {} path frames at {}x{}: {:.0} triangles and {:.0} px covered a frame, \
             rasterized in {:.3} ms a frame ({:.0} ns a triangle, {} threads), \
             {:.2}x the shading pass ({:.3} ms); buffers' digest {}",
            report.scene,
            objects,
            if args.as_client {
                " (those a client draws as geometry)"
            } else {
                ""
            },
            report.frames,
            width,
            height,
            report.triangles_per_frame,
            report.covered_px,
            report.raster_ms,
            report.ns_per_triangle,
            report.threads,
            report.raster_to_shade,
            report.shade_ms,
            report.gbuffer_digest,
        );
    }
    Ok(())
}
