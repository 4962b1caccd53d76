//! `relief frame`: one composited frame — geometry plus impostors baked some degrees
//! away from the eye — and how long it took against the same frame as geometry.

use std::path::PathBuf;

use anyhow::{Result, anyhow};
use clap::Args;
use serde::Serialize;

use relief_core::relief::DepthBits;
use relief_lab::frame_plan::{FramePlan, FrameStats};
use relief_lab::image_error::compare;
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
    /// Also ray-trace the reference and report the frame's PSNR against it.
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
    #[serde(skip_serializing_if = "Option::is_none")]
    psnr_db: Option<f64>,
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
    let plan = FramePlan::bake(&scene, &camera, args.source_angle, DepthBits::Eight);
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
    let psnr_db = args.compare.then(|| {
        bar.set_message("ray-tracing the reference");
        let reference = render_reference(&SceneTracer::new(&scene), &camera, 1);
        compare(&frame, &reference, None).psnr_db
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
        psnr_db,
    };
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
            psnr_db.map_or(String::new(), |p| format!(
                "; PSNR {p:.1} dB against the reference"
            ))
        );
    }
    Ok(())
}
