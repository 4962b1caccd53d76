//! `relief demo`: the whole system on 127.0.0.1 — a server and workers as child
//! processes, and this client flying the scene's camera path with impostors,
//! asking for the textures it will need. Writes frames and `summary.json`.

mod judge;
mod summary;
mod timings;
mod worst;

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;

use relief_client::flight::{Flight, WARM_UP_LIMIT};
use relief_client::intake::Intake;
use relief_client::link::Link;
use relief_client::manager::{Config, late_fraction};
use relief_client::source::{local_manager, remote_manager};
use relief_core::camera::Camera;
use relief_core::scene::Scene;
use relief_core::stats::{finite_mean, finite_median, finite_min, median, percentile};
use relief_proto::bundle::bundle_for;
use relief_render::gbuffer::GBuffer;
use relief_render::geometry::render_geometry;

use judge::{Compared, KeptForJudging, by_object, judge};
use summary::{FrameStages, Summary};
use timings::FrameTimings;

use crate::processes::{LocalService, connect_and_upload, sibling};
use crate::window::Viewer;
use crate::{args, progress};

#[derive(Args)]
pub struct DemoArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Path frames to fly, at --fps (default: the scene's whole camera path). The eye
    /// follows the clock, so a slow frame skips path frames rather than slowing it.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    frames: Option<u32>,
    /// Output directory: frame_NNNNN.png, summary.json, psnr.csv, frames.csv,
    /// worst_frame*.png, worst_OBJECT.png (and warps/ with --warp-samples).
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
    /// This client's credential for the server given with --server (its
    /// --client-token, or its shared --token).
    #[arg(long, env = "RELIEF_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Send --token over plain http:// to a host other than this one (else refused:
    /// anyone on the path could read it).
    #[arg(long, env = "RELIEF_ALLOW_INSECURE")]
    allow_insecure: bool,
    /// Network delay injected on the client side (half each way), milliseconds.
    #[arg(long, default_value = "0", value_parser = clap::value_parser!(u64).range(0..=60_000))]
    rtt_ms: u64,
    /// Only ask for textures when they are needed (the baseline without prediction).
    #[arg(long)]
    no_predict: bool,
    /// Largest growth of the predicted warp gap (screen pixels) before a texture is
    /// replaced: the impostor lifetime knob.
    #[arg(long, default_value_t = relief_client::manager::policy::DEFAULT_TOLERANCE, allow_hyphen_values = true, value_parser = args::positive)]
    tolerance: f32,
    /// Triangles a frame may draw as geometry in the stead of objects without a valid
    /// texture, nearest first, each that still fits (0: none; such objects count as
    /// stale).
    #[arg(long, default_value_t = relief_client::manager::policy::STAND_IN_TRIANGLES)]
    stand_in_triangles: usize,
    /// Compare with the ray-traced reference every K-th frame (0: never).
    #[arg(long, default_value = "20")]
    reference_every: u32,
    /// Time the all-geometry frame every K-th frame.
    #[arg(long, default_value = "10", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    geometry_every: u32,
    /// Write every K-th frame as PNG (0: none).
    #[arg(long, default_value = "10")]
    write_every: u32,
    /// Keep about one in K successful pre-warps of the flight (up to the client's
    /// `MAX_WARP_SAMPLES`, and `MAX_WARP_SAMPLE_TEXELS` of textures) and write them to
    /// OUT/warps after it (made anew), for `relief bench replay` to time again (0:
    /// none).
    #[arg(long, default_value = "0")]
    warp_samples: u32,
    /// Frame size WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360", value_parser = args::frame_size)]
    size: (u32, u32),
    /// Frames per second the camera moves at (frames are paced to it).
    #[arg(long, default_value = "30", value_parser = clap::value_parser!(u32).range(1..=1000))]
    fps: u32,
    /// Exit with an error when more than this fraction of the frames were stale (an
    /// impostor shown past its tolerance, or missing): a run the service did not keep
    /// up with. 1 never fails.
    #[arg(long, default_value_t = DEFAULT_MAX_STALE_FRAC, value_parser = args::fraction)]
    max_stale_frac: f64,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    /// Show the frames in a window as they are drawn (Escape or closing it ends the
    /// flight early). Needs a build with the `window` feature and a display.
    #[arg(long)]
    window: bool,
}

/// `--max-stale-frac`'s default: a quarter of the frames stale is a run that went
/// without its textures for long stretches (healthy loopback runs: 0–2 %, 100 ms
/// round trips included), not one a slow frame or two spoiled.
const DEFAULT_MAX_STALE_FRAC: f64 = 0.25;

/// Memory the frames kept for comparison after the flight may take: the demo's
/// default flight judged every frame at 640×360 (1.5 MiB a frame) would keep 677 MiB.
const MAX_COMPARED_BYTES: usize = 256 << 20;

pub fn run(args: DemoArgs) -> Result<()> {
    let scene = Arc::new(crate::args::load_scene(&args.scene)?);
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
        stand_in_triangles: args.stand_in_triangles,
        ..Config::default()
    };
    // (`health`: whether the server could serve, for a run with one.)
    let (mut manager, source, health) = match &url {
        Some(url) => {
            let _guard = runtime.enter();
            relief_proto::connect::refuse_token_in_clear(url, args.token.as_deref(), args.allow_insecure)?;
            let bundle = Arc::new(bundle_for(&args.scene)?);
            // Workers we started must have registered; a given server has its own.
            let (remote, hash) = runtime.block_on(connect_and_upload(
                url,
                args.token.as_deref(),
                args.tls_ca.as_deref(),
                &format!("demo-{}", std::process::id()),
                &bundle,
                started_workers,
            ))?;
            let rtt = Duration::from_millis(args.rtt_ms);
            let link = Link::new(remote, bundle, hash);
            // (A server without a worker is known before the first request.)
            runtime.block_on(link.look());
            let health = link.health.clone();
            (
                remote_manager(&scene, config, link, rtt, Intake::default()),
                format!("server {url}"),
                Some(health),
            )
        }
        None => (
            local_manager(&scene, config),
            "in-process generator".to_string(),
            None,
        ),
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
    manager.sample_warps(args.warp_samples);
    let bar = progress::bar(flight.frames as u64, "flying");
    // Every K-th frame's camera, drawn all as geometry after the flight (see below).
    let (mut geometry_cameras, mut geometry_frames) = (Vec::new(), Vec::new());
    // A kept frame: colour and object id per pixel.
    let frame_bytes = w as usize * h as usize * 7;
    let mut compared = KeptForJudging::new(args.reference_every, frame_bytes, MAX_COMPARED_BYTES);
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
            if compared.wants(index) {
                // Judged after the flight: tracing references here would stall it.
                compared.keep(Compared {
                    path_frame: flown.path_frame,
                    camera: *camera,
                    image,
                    shown: flown.shown,
                });
            }
            if index.is_multiple_of(args.geometry_every) {
                geometry_cameras.push(*camera);
                geometry_frames.push(index as usize);
            }
            bar.set_position(flown.path_frame as u64 + 1);
            Ok(ControlFlow::Continue(()))
        },
    )?;
    bar.finish_and_clear();
    let (samples, left_out) = manager.take_warp_samples();
    if !samples.is_empty() {
        crate::warp_files::write_samples(&args.out.join("warps"), &samples, &scene)?;
    }
    if left_out > 0 {
        eprintln!(
            "warning: kept {} pre-warps and left {left_out} more out, the limits reached (`MAX_WARP_SAMPLES`, `MAX_WARP_SAMPLE_TEXELS`): raise --warp-samples",
            samples.len()
        );
    }
    let compared_every = compared.every();
    if compared_every > args.reference_every {
        eprintln!(
            "warning: compared one frame in {compared_every}, not one in {}: more would pass the {} MiB the frames kept for judging may take (the summary's `compared_every`; a smaller --size or fewer --frames keeps more)",
            args.reference_every,
            MAX_COMPARED_BYTES >> 20
        );
    }
    let judged = judge(&scene, &compared.into_kept(), &args.out)?;
    let counters = &manager.counters;
    let lifetimes = manager.texture_lifetimes();
    let mut summary = Summary {
        frames: log.frames,
        path_frames: flight.frames,
        frame_ms_p50: median(log.frame_ms.clone()),
        frame_ms_p95: percentile(&log.frame_ms, 0.95),
        // (Timed below, once the service has stopped.)
        geometry_frame_ms_p50: f64::NAN,
        geometry_over_frame_paired_p50: f64::NAN,
        frame_stages_ms_p50: FrameStages::median(&log.records, &counters.render_stages),
        requests_now: counters.requests_now,
        requests_predicted: counters.requests_predicted,
        withdrawn: counters.withdrawn,
        requests_failed: counters.requests_failed,
        requests_timed_out: counters.requests_timed_out,
        requests_open_at_exit: manager.requests_open(),
        requests_shed: counters.requests_shed,
        textures_shared: counters.textures_shared,
        load_scale_mean: counters.load_scale_sum / f64::from(log.frames.max(1)),
        link_scale_mean: counters.link_scale_sum / f64::from(log.frames.max(1)),
        degraded_s: health.as_ref().map(|h| h.degraded_s()),
        latency_ms_p50: percentile(&counters.latencies_ms, 0.5),
        latency_ms_p99: percentile(&counters.latencies_ms, 0.99),
        latency_now_ms_p99: percentile(&counters.latencies_now_ms, 0.99),
        predictions_late_frac: late_fraction(&counters.prediction_lateness_ms),
        pickup_ms_p50: percentile(&counters.pickup_ms, 0.5),
        pickup_ms_p99: percentile(&counters.pickup_ms, 0.99),
        texture_lifetime_s_p10: percentile(&lifetimes.seconds, 0.1),
        texture_lifetime_s_p50: percentile(&lifetimes.seconds, 0.5),
        textures_never_shown: lifetimes.never_shown,
        textures_never_shown_superseded: lifetimes.superseded,
        prediction_hits: counters.prediction_hits,
        needs: counters.needs,
        stale_frames: counters.stale_frames,
        stale_causes: counters.stale_causes,
        stand_ins: counters.stand_ins,
        sprites: counters.sprites,
        warps: counters.warps,
        partners: counters.partners,
        texels_warped_per_frame: counters.texels_warped() as f64 / log.frames.max(1) as f64,
        regenerations_per_orbit: log.regenerations_per_orbit(),
        psnr_db_mean: finite_mean(&judged.psnr),
        psnr_db_min: finite_min(&judged.psnr),
        psnr_whole_db_min: finite_min(&judged.psnr_whole),
        hole_frac_max: judged.hole_frac.iter().copied().reduce(f64::max),
        psnr_aa_db_mean: finite_mean(&judged.psnr_aa),
        psnr_aa_db_min: finite_min(&judged.psnr_aa),
        geometry_psnr_aa_db_min: finite_min(&judged.geometry_psnr_aa),
        psnr_aa_db_min_by_object: by_object(&judged.by_object, finite_min),
        geometry_psnr_aa_db_min_by_object: by_object(&judged.geometry_by_object, finite_min),
        psnr_aa_db_median_by_object: by_object(&judged.by_object, finite_median),
        geometry_psnr_aa_db_median_by_object: by_object(&judged.geometry_by_object, finite_median),
        psnr_aa_gap_db_min_by_object: by_object(&judged.gap_by_object, finite_min),
        psnr_aa_gap_db_median_by_object: by_object(&judged.gap_by_object, finite_median),
        compared_every,
        rtt_ms: args.rtt_ms,
        predict: !args.no_predict,
        tolerance: args.tolerance,
        workers: started_workers,
        source,
    };
    // The service stopped (the workers' processes, or the in-process generator once
    // its bake in hand is done), so that nothing but the geometry frames runs while
    // they are timed.
    let textures_held = manager.textures_held();
    let render_stages = std::mem::take(&mut manager.counters.render_stages);
    drop(manager);
    drop(service);
    let geometry_ms = time_geometry(&scene, &geometry_cameras, (w, h));
    summary.geometry_frame_ms_p50 = median(geometry_ms.clone());
    let frame_timings = FrameTimings::new(&log, &render_stages, &geometry_frames, &geometry_ms)?;
    summary.geometry_over_frame_paired_p50 = median(frame_timings.paired_ratios());
    frame_timings.write_csv(&args.out)?;
    let json = serde_json::to_string_pretty(&summary)?;
    std::fs::write(args.out.join("summary.json"), &json).context("writing summary.json")?;
    if args.json {
        println!("{json}");
    } else {
        println!("{}", summary.line(args.size, &args.out));
    }
    let stale_frac = summary.stale_frames as f64 / summary.frames.max(1) as f64;
    if stale_frac > args.max_stale_frac {
        bail!(
            "{:.1} % of the frames were stale, over --max-stale-frac {:.1} %{}",
            100.0 * stale_frac,
            100.0 * args.max_stale_frac,
            match summary.degraded_s {
                Some(s) if s > 0.0 => format!(": the server could not serve for {s:.1} s"),
                _ => String::new(),
            }
        );
    }
    // Every frame drawn as geometry is not a run of the service: say so, and fail.
    if textures_held == 0 && summary.needs > 0 {
        bail!(
            "no relief texture arrived from {} in the whole run: is a worker connected to \
             the server? Every frame was drawn as geometry",
            summary.source
        );
    }
    Ok(())
}

/// How long each of `cameras`' frames takes drawn all as geometry, in milliseconds.
/// Timed after the flight, not in it: a large scene's geometry frame takes longer than
/// several of the flight's frames, and in the flight each would stall the clock the eye
/// follows, and jump the eye as a user's client never does. (So the demo's own workers
/// have stopped by then while the flight's frames shared the cores with them: the ratio
/// of the two errs against the impostors.)
fn time_geometry(scene: &Scene, cameras: &[Camera], (w, h): (u32, u32)) -> Vec<f64> {
    let bar = progress::bar(cameras.len() as u64, "timing the frames as geometry");
    let mut gbuffer = GBuffer::new(w, h);
    let ms = (cameras.iter())
        .map(|camera| {
            let began = Instant::now();
            drop(render_geometry(scene, camera, &mut gbuffer));
            bar.inc(1);
            began.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    bar.finish_and_clear();
    ms
}
