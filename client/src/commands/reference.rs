//! `relief reference`: a ray-traced, Phong-lit frame of the whole scene.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use relief_worker::{SceneTracer, render_reference};

use crate::{args, progress};

#[derive(Args)]
pub struct ReferenceArgs {
    #[command(flatten)]
    view: args::View,
    /// Output PNG file.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: ReferenceArgs) -> Result<()> {
    let bar = progress::spinner("loading scene");
    let (scene, camera) = args.view.load()?;
    let (w, h) = (camera.width, camera.height);
    bar.set_message("building BVHs");
    let tracer = SceneTracer::new(&scene);
    bar.set_message("tracing");
    let frame = render_reference(&tracer, &camera);
    bar.finish_and_clear();
    frame.save_png(&args.out)?;
    tracing::info!("reference {w}x{h} of `{}` -> {}", scene.name, args.out.display());
    Ok(())
}
