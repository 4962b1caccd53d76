//! `relief bake`: the relief texture of one object for an eye, written to a directory.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use glam::DVec3;

use relief_core::relief::DepthBits;
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

use crate::args;

#[derive(Args)]
pub struct BakeArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Object to bake; may be omitted when the scene has one object.
    #[arg(long)]
    object: Option<String>,
    /// Eye the texture is made for, X,Y,Z in the world (outside the object's bounds).
    /// The texture is written in the object's own frame: texture.json's coordinates
    /// are measured from the object's origin (its `translate`).
    #[arg(long, value_parser = args::position, allow_hyphen_values = true)]
    eye: DVec3,
    /// Texture edge in texels (square), 1..=4096.
    #[arg(long, default_value = "256", value_parser = args::texture_size, allow_hyphen_values = true)]
    size: u32,
    /// Depth precision: 8 (levels 0..254, 255 empty) or 16 (0..65534, 65535 empty).
    #[arg(long, default_value = "8", value_parser = args::depth_bits)]
    depth_bits: u32,
    /// Which way the texels' rays go: parallel (the thesis's relief texture) or from
    /// the eye (what the eye sees; the client asks for these).
    #[arg(long, value_enum, default_value_t = args::ProjectionArg::Orthographic)]
    projection: args::ProjectionArg,
    /// Output directory: albedo.png, normal.png, depth.png, texture.json.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: BakeArgs) -> Result<()> {
    // The directory first: a bad --out fails before the bake. One made here is taken
    // away again (while still empty) when anything else fails.
    let made = !args.out.exists();
    std::fs::create_dir_all(&args.out).with_context(|| format!("--out {}", args.out.display()))?;
    let baked = bake_into(&args);
    if baked.is_err() && made {
        let _ = std::fs::remove_dir(&args.out);
    }
    baked
}

/// The bake of `run`, its output directory made.
fn bake_into(args: &BakeArgs) -> Result<()> {
    let scene = crate::args::load_scene(&args.scene)?;
    let object = scene.object_or_only(args.object.as_deref())?;
    let tracer = ObjectTracer::new(object);
    let texture = bake(
        &tracer,
        object.to_local(args.eye),
        args.size,
        DepthBits::from_bits(args.depth_bits)?,
        args.projection.into(),
    )?;
    texture.write_dir(&args.out)?;
    tracing::info!(
        "baked `{}` at {}x{}: {} of {} texels covered -> {}",
        object.name,
        args.size,
        args.size,
        texture.covered_texels(),
        texture.depth.len(),
        args.out.display()
    );
    Ok(())
}
