//! `relief reference`: a ray-traced, Phong-lit frame of the whole scene.

use std::path::PathBuf;

use anyhow::{Result, anyhow};
use clap::Args;
use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::scene::Scene;
use relief_worker::{SceneTracer, render_reference};

use crate::{args, progress};

#[derive(Args)]
pub struct ReferenceArgs {
    /// Built-in scene name, .toml scene file, or .obj file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Camera position, X,Y,Z.
    #[arg(long, value_parser = args::vec3, allow_hyphen_values = true)]
    eye: Vec3,
    /// Point the camera looks at, X,Y,Z.
    #[arg(long, value_parser = args::vec3, allow_hyphen_values = true)]
    target: Vec3,
    /// Up direction, X,Y,Z.
    #[arg(long, default_value = "0,1,0", value_parser = args::vec3, allow_hyphen_values = true)]
    up: Vec3,
    /// Vertical field of view in degrees (default: the scene's).
    #[arg(long)]
    fov: Option<f32>,
    /// Frame size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = args::frame_size)]
    size: (u32, u32),
    /// Output PNG file.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: ReferenceArgs) -> Result<()> {
    let bar = progress::spinner("loading scene");
    let scene = Scene::load(&args.scene)?;
    let fov = args.fov.unwrap_or(scene.fov_y_degrees);
    let (w, h) = args.size;
    let camera = Camera::look_at(args.eye, args.target, args.up, fov, w, h).map_err(|e| anyhow!(e))?;
    bar.set_message("building BVHs");
    let tracer = SceneTracer::new(&scene);
    bar.set_message("tracing");
    let frame = render_reference(&tracer, &camera);
    bar.finish_and_clear();
    frame.save_png(&args.out)?;
    tracing::info!("reference {w}x{h} of `{}` -> {}", scene.name, args.out.display());
    Ok(())
}
