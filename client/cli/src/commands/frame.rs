//! `relief frame`: one composited frame — geometry plus impostors baked some degrees
//! away from the eye — and how long it took against the same frame as geometry.

use std::path::PathBuf;

use anyhow::{Result, anyhow};
use clap::Args;
use serde::Serialize;

use relief_client::manager::policy::REQUESTED_DEPTH_BITS;
use relief_lab::frame_plan::{FramePlan, FrameStats};
use relief_lab::image_error::{MAX_HOLE_FRAC, compare};
use relief_lab::methods::Method;
use relief_lab::timing::{median_ms, median_ms_after};
use relief_render::gbuffer::GBuffer;
use relief_render::geometry::render_geometry;
use relief_trace::{SceneTracer, render_reference};

use crate::{args, progress};

#[derive(Args)]
pub struct FrameArgs {
    #[command(flatten)]
    view: args::View,
    /// Display method (sprite is not available without a previous frame).
    #[arg(long, default_value = "interleaved")]
    method: Method,
    /// Bake each impostor this many degrees around its object from the eye.
    #[arg(long, default_value = "5", allow_hyphen_values = true, value_parser = args::finite)]
    source_angle: f32,
    /// Timed runs of each frame (the median is reported), after one warm-up.
    #[arg(long, default_value = "5", value_parser = clap::value_parser!(u32).range(1..=1000))]
    runs: u32,
    /// Also ray-trace the reference and report the frame's error against it: PSNR and
    /// SSIM over the pixels both show, PSNR over every pixel either shows, and the
    /// fraction shown by only one.
    #[arg(long)]
    compare: bool,
    /// Output PNG file.
    #[arg(long, value_parser = args::png_path)]
    out: PathBuf,
    /// Print the numbers as one JSON object.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct FrameReport {
    impostors: Vec<String>,
    geometry: Vec<String>,
    frame_ms: f64,
    geometry_frame_ms: f64,
    speedup: f64,
    #[serde(flatten)]
    stats: FrameStats,
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    error: Option<FrameError>,
}

/// The frame against the ray-traced reference (`--compare`): see
/// [`ImageError`](relief_lab::image_error::ImageError).
#[derive(Serialize)]
struct FrameError {
    /// Over the pixels both show.
    #[serde(serialize_with = "relief_lab::image_error::serialize_psnr")]
    psnr_db: f64,
    /// Over every pixel either shows: coverage counts.
    #[serde(serialize_with = "relief_lab::image_error::serialize_psnr")]
    psnr_whole_db: f64,
    ssim: f64,
    /// Of the pixels either shows, those only one does.
    hole_frac: f64,
    /// `hole_frac` within [`MAX_HOLE_FRAC`]: only then does `psnr_db` speak for the
    /// frame.
    covers_reference: bool,
}

pub fn run(args: FrameArgs) -> Result<()> {
    if args.method == Method::Sprite {
        return Err(anyhow!(
            "--method sprite needs a previous frame; choose a warp method"
        ));
    }
    args::ensure_writable("--out", &args.out)?;
    let bar = progress::spinner("loading scene");
    let (scene, camera) = args.view.load()?;
    let (w, h) = (camera.width, camera.height);
    bar.set_message("baking impostors");
    let plan = FramePlan::bake(&scene, &camera, args.source_angle, REQUESTED_DEPTH_BITS);
    bar.set_message("rendering");
    let runs = args.runs as usize;
    let mut drawn = (GBuffer::new(w, h), None);
    let frame_ms = median_ms_after(
        runs,
        &mut drawn,
        |_| {},
        |(gbuffer, result)| *result = Some(plan.render(&scene, &camera, args.method, gbuffer)),
    );
    let (mut gbuffer, result) = drawn;
    let Some((frame, stats)) = result else {
        return Err(anyhow!("no frame rendered"));
    };
    let geometry_frame_ms = median_ms(runs, || drop(render_geometry(&scene, &camera, &mut gbuffer)));
    let error = args.compare.then(|| {
        bar.set_message("ray-tracing the reference");
        let reference = render_reference(&SceneTracer::new(&scene), &camera, 1);
        let e = compare(&frame, &reference, None);
        FrameError {
            psnr_db: e.psnr_db,
            psnr_whole_db: e.psnr_whole_db,
            ssim: e.ssim,
            hole_frac: e.hole_frac,
            covers_reference: e.covers_reference(),
        }
    });
    bar.finish_and_clear();
    frame.save_png(&args.out)?;
    let name = |k: u32| scene.objects[k as usize].name.clone();
    let report = FrameReport {
        impostors: plan.impostors.iter().map(|i| name(i.index)).collect(),
        geometry: plan.geometry.iter().map(|&(k, _)| name(k)).collect(),
        frame_ms,
        geometry_frame_ms,
        speedup: geometry_frame_ms / frame_ms,
        stats,
        error,
    };
    for why in &report.stats.fell_back_why {
        eprintln!("warning: drawn as geometry instead: {why}");
    }
    if let Some(e) = &report.error
        && !e.covers_reference
    {
        eprintln!(
            "warning: {:.0} % of the pixels either frame shows are shown by one only (more \
             than {:.0} %): the PSNR over the pixels both show does not speak for this frame; \
             read psnr_whole_db",
            100.0 * e.hole_frac,
            100.0 * MAX_HOLE_FRAC
        );
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{w}x{h} frame with {} as impostors ({}), {} as geometry: {:.2} ms; all geometry {:.2} ms ({:.1}x){}",
            report.impostors.join(", "),
            args.method,
            report.geometry.join(", "),
            frame_ms,
            geometry_frame_ms,
            report.speedup,
            report.error.as_ref().map_or(String::new(), |e| format!(
                "; against the reference: PSNR {:.1} dB and SSIM {:.3} where both show, \
                 {:.1} dB over every pixel either shows, {:.1} % shown by one only",
                e.psnr_db,
                e.ssim,
                e.psnr_whole_db,
                100.0 * e.hole_frac
            ))
        );
    }
    Ok(())
}
