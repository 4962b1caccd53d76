//! `relief demo`: the whole system on 127.0.0.1 — a server and workers as child
//! processes, and this client flying the scene's camera path with impostors,
//! asking for the textures it will need. Writes frames and `summary.json`.

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;

use relief_client::flight::{Flight, WARM_UP_LIMIT};
use relief_client::manager::{Config, RenderStages, StaleCauses};
use relief_client::source::{local_manager, remote_manager};
use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::scene::Scene;
use relief_core::stats::{finite_mean, finite_min, median, percentile};
use relief_lab::image_error::{compare, object_psnr};
use relief_proto::bundle::bundle_for;
use relief_render::gbuffer::GBuffer;
use relief_render::geometry::{is_cheap, render_geometry};
use relief_trace::{ANTIALIASED_SAMPLES, SceneTracer, render_reference};

use crate::processes::{LocalService, connect_and_upload, sibling};
use crate::window::Viewer;
use crate::{args, progress};

#[derive(Args)]
pub struct DemoArgs {
    /// Built-in scene name, .toml scene file, or .obj file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Path frames to fly, at --fps (default: the scene's whole camera path). The eye
    /// follows the clock, so a slow frame skips path frames rather than slowing it.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    frames: Option<u32>,
    /// Output directory: frame_NNNNN.png, summary.json, psnr.csv, worst_frame*.png.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Workers to start (with --server, the server's own workers serve instead).
    #[arg(long, default_value = "2", value_parser = clap::value_parser!(u32).range(1..=64))]
    workers: u32,
    /// Use this server instead of starting one (e.g. http://10.0.0.5:7411).
    #[arg(long, env = "RELIEF_SERVER")]
    pub server: Option<String>,
    /// PEM file of certificates to trust for an `https://` --server.
    #[arg(long, env = "RELIEF_TLS_CA")]
    tls_ca: Option<PathBuf>,
    /// Shared secret of the server given with --server.
    #[arg(long, env = "RELIEF_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Network delay injected on the client side (half each way), milliseconds.
    #[arg(long, default_value = "0", value_parser = clap::value_parser!(u64).range(0..=60_000))]
    rtt_ms: u64,
    /// Only ask for textures when they are needed (the baseline without prediction).
    #[arg(long)]
    no_predict: bool,
    /// Largest growth of the predicted warp gap (screen pixels) before a texture is
    /// replaced: the impostor lifetime knob.
    #[arg(long, default_value = "24", allow_hyphen_values = true, value_parser = args::positive)]
    tolerance: f32,
    /// Compare with the ray-traced reference every K-th frame (0: never).
    #[arg(long, default_value = "20")]
    reference_every: u32,
    /// Time the all-geometry frame every K-th frame.
    #[arg(long, default_value = "10", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    geometry_every: u32,
    /// Write every K-th frame as PNG (0: none).
    #[arg(long, default_value = "10")]
    write_every: u32,
    /// Frame size WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360", value_parser = args::frame_size)]
    size: (u32, u32),
    /// Frames per second the camera moves at (frames are paced to it).
    #[arg(long, default_value = "30", value_parser = clap::value_parser!(u32).range(1..=1000))]
    fps: u32,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    /// Show the frames in a window as they are drawn (Escape or closing it ends the
    /// flight early). Needs a build with the `window` feature and a display.
    #[arg(long)]
    window: bool,
}

/// The stages of the demo's frames, milliseconds.
#[derive(Serialize)]
struct FrameStages {
    /// The impostor manager's decisions and requests.
    plan: f64,
    /// Deciding which impostors are warped (or redrawn as sprites), and their
    /// pre-warps.
    prewarp: f64,
    /// Impostors drawn: pre-warps texture-mapped, sprites redrawn.
    draw: f64,
    /// Objects drawn as geometry.
    geometry: f64,
    /// Lighting.
    shade: f64,
}

impl FrameStages {
    fn median(plan_ms: &[f64], render: &[RenderStages]) -> FrameStages {
        let of = |stage: fn(&RenderStages) -> f64| median(render.iter().map(stage).collect());
        FrameStages {
            plan: median(plan_ms.to_vec()),
            prewarp: of(|r| r.prewarp_ms),
            draw: of(|r| r.draw_ms),
            geometry: of(|r| r.geometry_ms),
            shade: of(|r| r.shade_ms),
        }
    }
}

/// What `summary.json` holds.
#[derive(Serialize)]
struct Summary {
    /// Frames rendered (path frames a slow frame skipped are not rendered).
    frames: u32,
    /// Path frames flown.
    path_frames: u32,
    frame_ms_p50: f64,
    frame_ms_p95: f64,
    geometry_frame_ms_p50: f64,
    /// Where the frame time goes, each stage's median on its own.
    frame_stages_ms_p50: FrameStages,
    requests_now: u64,
    requests_predicted: u64,
    withdrawn: u64,
    latency_ms_p50: f64,
    latency_ms_p99: f64,
    /// Needed textures already there or in flight, and the needs counted.
    prediction_hits: u64,
    needs: u64,
    stale_frames: u64,
    /// Object-frames without a valid texture, by cause.
    stale_causes: StaleCauses,
    /// Impostors redrawn unchanged while Schaufler's sprite test held, and warped.
    sprites: u64,
    warps: u64,
    partners: u64,
    /// Texels pre-warped per frame drawn, warps and partners together.
    texels_warped_per_frame: f64,
    /// New textures received per full turn for each object orbited by the path.
    regenerations_per_orbit: BTreeMap<String, f64>,
    /// Against the point-sampled reference (one ray through each pixel centre);
    /// `null` when no frame was compared (`--reference-every 0`).
    psnr_db_mean: Option<f64>,
    psnr_db_min: Option<f64>,
    /// Against the anti-aliased reference (3×3 rays per pixel) …
    psnr_aa_db_mean: Option<f64>,
    psnr_aa_db_min: Option<f64>,
    /// … which the same frames drawn all as exact geometry, one sample per pixel, do
    /// not reach either: the floor that detail finer than a pixel sets.
    geometry_psnr_aa_db_min: Option<f64>,
    /// Per object that may be an impostor, the lowest PSNR of its own pixels against
    /// the anti-aliased reference — wherever either frame shows it, so silhouette
    /// errors count.
    psnr_aa_db_min_by_object: BTreeMap<String, f64>,
    /// … and the floor for it: the object drawn as exact geometry, one sample per
    /// pixel, against the anti-aliased reference.
    geometry_psnr_aa_db_min_by_object: BTreeMap<String, f64>,
    rtt_ms: u64,
    predict: bool,
    tolerance: f32,
    /// Workers started; `None` with `--server` (whose own workers serve) or when no
    /// server could start (textures made in-process).
    workers: Option<u32>,
    source: String,
}

/// Memory the frames kept for comparison after the flight may take.
const MAX_COMPARED_BYTES: usize = 256 << 20;

/// The image error of the compared frames, each as drawn and as all geometry.
#[derive(Default)]
struct Judged {
    psnr: Vec<f64>,
    psnr_aa: Vec<f64>,
    geometry_psnr_aa: Vec<f64>,
    /// Per object that may be an impostor: its own PSNR in each frame showing it
    /// ([`object_psnr`]) against the anti-aliased reference, as drawn and as exact
    /// geometry.
    by_object: BTreeMap<String, Vec<f64>>,
    geometry_by_object: BTreeMap<String, Vec<f64>>,
}

/// Compares each kept `(path frame, camera, frame)` with the ray-traced references;
/// writes `psnr.csv` and the worst frame with its reference into `out`.
fn judge(scene: &Scene, compared: &[(u32, Camera, Frame)], out: &Path) -> Result<Judged> {
    let mut judged = Judged::default();
    if compared.is_empty() {
        return Ok(judged);
    }
    let bar = progress::bar(compared.len() as u64, "comparing with the reference");
    let tracer = SceneTracer::new(scene);
    // Objects that may be impostors: each gets its own columns.
    let candidates: Vec<(u32, &str)> = scene
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| !is_cheap(o))
        .map(|(k, o)| (k as u32, o.name.as_str()))
        .collect();
    // Names become column names: keep the CSV's commas and quotes out of them.
    let column = |name: &str| name.replace(|c: char| !(c.is_alphanumeric() || c == '_' || c == '-'), "_");
    let mut log = String::from("frame,psnr_db,psnr_aa_db,geometry_psnr_aa_db");
    for (_, name) in &candidates {
        let name = column(name);
        log.push_str(&format!(",psnr_aa_db_{name},geometry_psnr_aa_db_{name}"));
    }
    log.push('\n');
    let mut worst = f64::INFINITY;
    for (frame, camera, image) in compared {
        let reference = render_reference(&tracer, camera, 1);
        let antialiased = render_reference(&tracer, camera, ANTIALIASED_SAMPLES);
        let geometry = render_geometry(scene, camera, &mut GBuffer::new(camera.width, camera.height));
        let p = compare(image, &reference, None).psnr_db;
        let p_aa = compare(image, &antialiased, None).psnr_db;
        let floor = compare(&geometry, &antialiased, None).psnr_db;
        log.push_str(&format!("{frame},{p:.3},{p_aa:.3},{floor:.3}"));
        for &(k, name) in &candidates {
            let own = object_psnr(image, &antialiased, k);
            let own_floor = object_psnr(&geometry, &antialiased, k);
            for (value, into) in [
                (own, &mut judged.by_object),
                (own_floor, &mut judged.geometry_by_object),
            ] {
                log.push(',');
                if let Some(v) = value {
                    log.push_str(&format!("{v:.3}"));
                    into.entry(name.to_string()).or_default().push(v);
                }
            }
        }
        log.push('\n');
        if p < worst {
            worst = p;
            image.save_png(&out.join("worst_frame.png"))?;
            reference.save_png(&out.join("worst_frame_reference.png"))?;
        }
        judged.psnr.push(p);
        judged.psnr_aa.push(p_aa);
        judged.geometry_psnr_aa.push(floor);
        bar.inc(1);
    }
    bar.finish_and_clear();
    std::fs::write(out.join("psnr.csv"), log).context("writing psnr.csv")?;
    Ok(judged)
}

/// The finite minimum of each object's values.
fn min_by_object(values: &BTreeMap<String, Vec<f64>>) -> BTreeMap<String, f64> {
    values
        .iter()
        .filter_map(|(name, values)| Some((name.clone(), finite_min(values)?)))
        .collect()
}

pub fn run(args: DemoArgs) -> Result<()> {
    let scene = Arc::new(Scene::load(&args.scene)?);
    let (w, h) = args.size;
    // First, so that a missing display fails before any process starts.
    let mut viewer = match args.window {
        true => Some(Viewer::open("relief demo — Escape ends the flight", w, h)?),
        false => None,
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let bar = progress::spinner("starting server and workers");
    // The server and workers this run starts: none with --server, nor when they cannot
    // start (then textures are made in-process).
    let service = match &args.server {
        Some(_) => None,
        None => match sibling("relief-worker").and_then(|_| LocalService::start(&args.out, args.workers)) {
            Ok(service) => Some(service),
            Err(e) => {
                eprintln!("warning: no server ({e:#}); generating textures in-process");
                None
            }
        },
    };
    let url = args.server.clone().or(service.as_ref().map(|s| s.url.clone()));
    let started_workers = service.as_ref().map(|_| args.workers);
    let config = Config {
        tolerance: args.tolerance,
        predict: !args.no_predict,
        ..Config::default()
    };
    let (mut manager, source) = match &url {
        Some(url) => {
            let _guard = runtime.enter();
            // Workers we started must have registered; a given server has its own.
            let (remote, hash) = runtime.block_on(connect_and_upload(
                url,
                args.token.as_deref(),
                args.tls_ca.as_deref(),
                &format!("demo-{}", std::process::id()),
                &bundle_for(&args.scene)?,
                started_workers,
            ))?;
            let rtt = Duration::from_millis(args.rtt_ms);
            (
                remote_manager(&scene, config, remote, hash, rtt),
                format!("server {url}"),
            )
        }
        None => (local_manager(&scene, config), "in-process generator".to_string()),
    };
    let flight = Flight {
        scene: &scene,
        size: args.size,
        fps: args.fps,
        frames: args.frames.unwrap_or(scene.path.frame_count().max(1)),
        start: 0,
        wrap: false,
    };
    bar.set_message("waiting for the first textures");
    if !flight.warm_up(&mut manager)? {
        eprintln!("warning: the first textures did not all arrive within {WARM_UP_LIMIT:?}");
    }
    bar.finish_and_clear();
    let bar = progress::bar(flight.frames as u64, "flying");
    let mut geometry_ms = Vec::new();
    let mut compared = Vec::new();
    let mut compare_every = args.reference_every;
    // A kept frame: colour and object id per pixel.
    let frame_bytes = (w as usize * h as usize * 7).max(1);
    let log = flight.fly(
        &mut manager,
        |_| true,
        |flown| -> Result<ControlFlow<()>> {
            let (index, camera) = (flown.index, flown.camera);
            let Some(image) = flown.image else {
                return Ok(ControlFlow::Continue(()));
            };
            if let Some(viewer) = &mut viewer
                && !viewer.show(&image)?
            {
                return Ok(ControlFlow::Break(()));
            }
            if args.write_every > 0 && index.is_multiple_of(args.write_every) {
                image.save_png(&args.out.join(format!("frame_{:05}.png", flown.path_frame)))?;
            }
            if compare_every > 0 && index.is_multiple_of(compare_every) {
                // Judged after the flight: tracing references here would stall it. A long
                // flight keeps every other one, comparing half as often, to stay within
                // the memory budget.
                compared.push((flown.path_frame, *camera, image));
                if compared.len() * frame_bytes > MAX_COMPARED_BYTES {
                    let mut k = 0;
                    compared.retain(|_| {
                        k += 1;
                        k % 2 == 1
                    });
                    compare_every *= 2;
                }
            }
            if index.is_multiple_of(args.geometry_every) {
                let mut all = GBuffer::new(w, h);
                let began = Instant::now();
                drop(render_geometry(&scene, camera, &mut all));
                geometry_ms.push(began.elapsed().as_secs_f64() * 1e3);
            }
            bar.set_position(flown.path_frame as u64 + 1);
            Ok(ControlFlow::Continue(()))
        },
    )?;
    bar.finish_and_clear();
    let judged = judge(&scene, &compared, &args.out)?;
    let counters = &manager.counters;
    let summary = Summary {
        frames: log.frames,
        path_frames: flight.frames,
        frame_ms_p50: median(log.frame_ms.clone()),
        frame_ms_p95: percentile(&log.frame_ms, 0.95),
        geometry_frame_ms_p50: median(geometry_ms),
        frame_stages_ms_p50: FrameStages::median(&log.plan_ms, &counters.render_stages),
        requests_now: counters.requests_now,
        requests_predicted: counters.requests_predicted,
        withdrawn: counters.withdrawn,
        latency_ms_p50: percentile(&counters.latencies_ms, 0.5),
        latency_ms_p99: percentile(&counters.latencies_ms, 0.99),
        prediction_hits: counters.prediction_hits,
        needs: counters.needs,
        stale_frames: counters.stale_frames,
        stale_causes: counters.stale_causes,
        sprites: counters.sprites,
        warps: counters.warps,
        partners: counters.partners,
        texels_warped_per_frame: counters.texels_warped as f64 / log.frames.max(1) as f64,
        regenerations_per_orbit: log.regenerations_per_orbit(),
        psnr_db_mean: finite_mean(&judged.psnr),
        psnr_db_min: finite_min(&judged.psnr),
        psnr_aa_db_mean: finite_mean(&judged.psnr_aa),
        psnr_aa_db_min: finite_min(&judged.psnr_aa),
        geometry_psnr_aa_db_min: finite_min(&judged.geometry_psnr_aa),
        psnr_aa_db_min_by_object: min_by_object(&judged.by_object),
        geometry_psnr_aa_db_min_by_object: min_by_object(&judged.geometry_by_object),
        rtt_ms: args.rtt_ms,
        predict: !args.no_predict,
        tolerance: args.tolerance,
        workers: started_workers,
        source,
    };
    let json = serde_json::to_string_pretty(&summary)?;
    std::fs::write(args.out.join("summary.json"), &json).context("writing summary.json")?;
    if args.json {
        println!("{json}");
    } else {
        println!(
            "{} frames ({}x{}) from {}: frame {:.1} ms p50 / {:.1} p95 (all geometry {:.1} ms); \
             {} requests now, {} predicted, latency {}; {} stale frames; PSNR {} -> {}",
            summary.frames,
            w,
            h,
            summary.source,
            summary.frame_ms_p50,
            summary.frame_ms_p95,
            summary.geometry_frame_ms_p50,
            summary.requests_now,
            summary.requests_predicted,
            if summary.latency_ms_p50.is_finite() {
                format!(
                    "{:.0} ms p50 / {:.0} p99",
                    summary.latency_ms_p50, summary.latency_ms_p99
                )
            } else {
                "not measured (no texture arrived during the flight)".to_string()
            },
            summary.stale_frames,
            match (summary.psnr_db_mean, summary.psnr_db_min) {
                (Some(mean), Some(min)) => format!("{mean:.1} dB mean, {min:.1} min"),
                _ => "not measured".to_string(),
            },
            args.out.display()
        );
    }
    drop(service);
    // Every frame drawn as geometry is not a run of the service: say so, and fail.
    if manager.textures_held() == 0 && summary.needs > 0 {
        bail!(
            "no relief texture arrived from {} in the whole run: is a worker connected to \
             the server? Every frame was drawn as geometry",
            summary.source
        );
    }
    Ok(())
}
