//! `relief bench replay`: the pre-warps a flight kept (`relief demo --warp-samples K`)
//! timed again, each alone, with its texture mapping into a frame of the flight's size:
//! the flight's own work, per object and projection, apart from what else its frames
//! did — what `relief bench warp`'s one texture seen a few degrees round does not show.
//!
//! Each replayed pre-warp must visit the texels the flight's did (the same texture and
//! camera: the same work); one that does not is an error.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Result, anyhow, bail};
use clap::Args;
use serde::Serialize;

use relief_core::scene::placed_object;
use relief_lab::timing::{median_ms, median_ms_after};
use relief_render::gbuffer::GBuffer;
use relief_render::warp::{Prewarped, Variant};

use crate::progress;
use crate::warp_files::{SavedWarp, read_sample, sample_dirs};

#[derive(Args)]
pub struct ReplayArgs {
    /// Directory of kept pre-warps: a demo's OUT/warps (`relief demo --warp-samples K`).
    dir: PathBuf,
    /// Timed runs of each pre-warp and mapping (the median is reported), after one
    /// warm-up.
    #[arg(long, default_value = "21", value_parser = clap::value_parser!(u32).range(1..=10000))]
    runs: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// One kept pre-warp, timed again.
#[derive(Serialize)]
struct Replayed {
    /// Its directory's name.
    name: String,
    object: String,
    perspective: bool,
    width: u32,
    height: u32,
    partner: bool,
    /// Texels visited (the flight's pre-warp visited as many).
    visited: usize,
    /// The pre-warp alone (`Prewarped::new`), ms.
    prewarp_ms: f64,
    /// Its texture mapping into a frame of the flight's size, ms.
    map_ms: f64,
    /// What the pre-warp took in the flight's frame, ms (see `WarpSample::in_frame_ms`:
    /// its own time only when the flight drew on one thread).
    in_frame_ms: f64,
}

/// The replayed pre-warps of one kind of object (its name without a placement's
/// number) and projection, summed.
#[derive(Serialize, Default)]
struct Group {
    warps: usize,
    visited: usize,
    prewarp_ms: f64,
    map_ms: f64,
    in_frame_ms: f64,
    /// `prewarp_ms` per texel visited, ns.
    prewarp_ns_per_texel: f64,
    /// The flight's, per texel visited, ns.
    in_frame_ns_per_texel: f64,
}

impl Group {
    fn add(&mut self, r: &Replayed) {
        self.warps += 1;
        self.visited += r.visited;
        self.prewarp_ms += r.prewarp_ms;
        self.map_ms += r.map_ms;
        self.in_frame_ms += r.in_frame_ms;
        let per_texel = |ms: f64| ms * 1e6 / self.visited.max(1) as f64;
        self.prewarp_ns_per_texel = per_texel(self.prewarp_ms);
        self.in_frame_ns_per_texel = per_texel(self.in_frame_ms);
    }
}

/// What `relief bench replay --json` prints.
#[derive(Serialize)]
struct ReplayReport {
    dir: PathBuf,
    runs: u32,
    threads: usize,
    warps: Vec<Replayed>,
    /// By kind and projection (`tree perspective`, `rock orthographic`, …), and `all`.
    groups: BTreeMap<String, Group>,
}

fn replay(warp: &SavedWarp, runs: usize) -> Result<Replayed> {
    let (impostor, camera) = (&warp.impostor, &warp.camera);
    let warped = || Prewarped::new(Variant::Interleaved, impostor, camera);
    let first = warped().map_err(|e| anyhow!("{}: {e}", warp.dir.display()))?;
    if first.texels_warped() != warp.visited {
        bail!(
            "{}: the replayed pre-warp visited {} texels where the flight's visited {}: not the same work",
            warp.dir.display(),
            first.texels_warped(),
            warp.visited
        );
    }
    let prewarp_ms = median_ms(runs, || drop(std::hint::black_box(warped())));
    // (The mapping takes its pre-warp: each run's is made, untimed, before it.)
    let mut state = (GBuffer::new(camera.width, camera.height), None);
    let map_ms = median_ms_after(
        runs,
        &mut state,
        |(frame, ready)| {
            frame.clear();
            *ready = warped().ok();
        },
        |(frame, ready)| {
            if let Some(prewarped) = ready.take() {
                prewarped.draw(impostor, 0, camera, frame);
            }
        },
    );
    let c = &impostor.texture.camera;
    Ok(Replayed {
        name: warp
            .dir
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into()),
        object: warp.object.clone(),
        perspective: c.centre.is_some(),
        width: c.width,
        height: c.height,
        partner: warp.partner,
        visited: warp.visited,
        prewarp_ms,
        map_ms,
        in_frame_ms: warp.in_frame_ms,
    })
}

pub fn run(args: ReplayArgs) -> Result<()> {
    let dirs = sample_dirs(&args.dir)?;
    let bar = progress::bar(dirs.len() as u64, "replaying pre-warps");
    let mut warps = Vec::new();
    // One at a time: a sample is a texture of up to many MB. Inside the pool, as a
    // frame draws (`Manager::render`): its halves' join forks there.
    rayon::scope(|_| -> Result<()> {
        for dir in &dirs {
            warps.push(replay(&read_sample(dir)?, args.runs as usize)?);
            bar.inc(1);
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    let mut groups: BTreeMap<String, Group> = BTreeMap::new();
    for r in &warps {
        let projection = if r.perspective {
            "perspective"
        } else {
            "orthographic"
        };
        groups
            .entry(format!("{} {projection}", placed_object(&r.object)))
            .or_default()
            .add(r);
        groups.entry("all".into()).or_default().add(r);
    }
    let report = ReplayReport {
        dir: args.dir,
        runs: args.runs,
        threads: rayon::current_num_threads(),
        warps,
        groups,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} pre-warps from {} replayed, {} runs each, {} threads; per texel visited:",
        report.warps.len(),
        report.dir.display(),
        report.runs,
        report.threads
    );
    println!(
        "{:<26} {:>6} {:>10} {:>12} {:>10} {:>14} {:>16}",
        "kind", "warps", "visited", "prewarp ms", "map ms", "prewarp ns/tx", "in frame ns/tx"
    );
    for (name, g) in &report.groups {
        println!(
            "{name:<26} {:>6} {:>10} {:>12.3} {:>10.3} {:>14.1} {:>16.1}",
            g.warps, g.visited, g.prewarp_ms, g.map_ms, g.prewarp_ns_per_texel, g.in_frame_ns_per_texel
        );
    }
    Ok(())
}
