//! `relief bench reference`: a reference frame walking the scene's objects through the
//! top-level BVH, nearest first, against tracing every object in turn (the same frame,
//! bit for bit).

use anyhow::{Context, Result, anyhow};
use clap::Args;
use serde::Serialize;

use relief_trace::reference::render_reference_by;
use relief_trace::{ObjectWalk, SceneTracer};

use crate::{args, progress};
use relief_lab::timing::best_ms;

#[derive(Args)]
pub struct ReferenceBenchArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "forest")]
    scene: String,
    /// The frame of the scene's camera path whose view is traced.
    #[arg(long, default_value = "0")]
    path_frame: u32,
    /// Frame size WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360", value_parser = args::frame_size)]
    size: (u32, u32),
    /// Rays per pixel edge (3: the anti-aliased reference the demo compares with).
    #[arg(long, default_value = "3", value_parser = clap::value_parser!(u32).range(1..=9))]
    samples: u32,
    /// Timed runs per walk (best is reported), after one warm-up.
    #[arg(long, default_value = "3", value_parser = clap::value_parser!(u32).range(1..=1000))]
    runs: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// What `relief bench reference --json` prints.
#[derive(Serialize)]
struct ReferenceReport {
    scene: String,
    objects: usize,
    path_frame: u32,
    width: u32,
    height: u32,
    samples: u32,
    /// Nearest first through the top-level BVH ([`ObjectWalk::NearestFirst`]).
    nearest_first_ms: f64,
    /// Every object in turn ([`ObjectWalk::EveryObject`]).
    every_object_ms: f64,
    /// `every_object_ms / nearest_first_ms`.
    speedup: f64,
    /// Both walks drew the same frame, bit for bit.
    identical: bool,
}

pub fn run(args: ReferenceBenchArgs) -> Result<()> {
    let bar = progress::spinner("loading scene");
    let scene = args::load_scene(&args.scene)?;
    let (width, height) = args.size;
    let pose = (scene.path.pose(args.path_frame))
        .with_context(|| format!("--path-frame {}: the scene has no camera path", args.path_frame))?;
    let camera =
        (pose.camera(scene.fov_y_degrees, width, height)).map_err(|e| anyhow!("--path-frame: {e}"))?;
    bar.set_message("building BVHs");
    let tracer = SceneTracer::new(&scene);
    let walk = |walk| render_reference_by(&tracer, &camera, args.samples, walk);
    bar.set_message("tracing, nearest first");
    let nearest_first = walk(ObjectWalk::NearestFirst);
    let nearest_first_ms = best_ms(args.runs as usize, || drop(walk(ObjectWalk::NearestFirst)));
    bar.set_message("tracing, every object");
    let every_object = walk(ObjectWalk::EveryObject);
    let every_object_ms = best_ms(args.runs as usize, || drop(walk(ObjectWalk::EveryObject)));
    bar.finish_and_clear();
    let report = ReferenceReport {
        scene: scene.name.clone(),
        objects: scene.objects.len(),
        path_frame: args.path_frame,
        width,
        height,
        samples: args.samples,
        nearest_first_ms,
        every_object_ms,
        speedup: every_object_ms / nearest_first_ms,
        identical: nearest_first.color == every_object.color && nearest_first.object == every_object.object,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{} ({} objects), path frame {}, {}x{} at {}² rays a pixel: nearest first {:.1} ms, every object {:.1} ms ({:.1}x){}",
            report.scene,
            report.objects,
            report.path_frame,
            width,
            height,
            report.samples,
            report.nearest_first_ms,
            report.every_object_ms,
            report.speedup,
            if report.identical {
                ""
            } else {
                "; THE FRAMES DIFFER"
            }
        );
    }
    if !report.identical {
        anyhow::bail!("the two walks drew different frames");
    }
    Ok(())
}
