//! `relief reference`: a ray-traced, Phong-lit frame of the whole scene.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use relief_trace::{SceneTracer, render_reference};

use crate::{args, progress};

#[derive(Args)]
pub struct ReferenceArgs {
    #[command(flatten)]
    view: args::View,
    /// Output PNG file.
    #[arg(long, value_parser = args::png_path)]
    out: PathBuf,
    /// Rays per pixel edge: N×N stratified rays averaged per pixel (anti-aliased); 1 is
    /// one ray through the pixel centre, as every frame compared with it samples.
    #[arg(long, default_value = "1", value_parser = clap::value_parser!(u32).range(1..=9))]
    samples: u32,
}

pub fn run(args: ReferenceArgs) -> Result<()> {
    args::ensure_writable("--out", &args.out)?;
    let bar = progress::spinner("loading scene");
    let (scene, camera) = args.view.load()?;
    let (w, h) = (camera.width, camera.height);
    bar.set_message("building BVHs");
    let tracer = SceneTracer::new(&scene);
    bar.set_message("tracing");
    let frame = render_reference(&tracer, &camera, args.samples);
    bar.finish_and_clear();
    frame.save_png(&args.out)?;
    tracing::info!("reference {w}x{h} of `{}` -> {}", scene.name, args.out.display());
    Ok(())
}
