//! The demo's compared frames, kept in the flight within a memory budget
//! ([`KeptForJudging`]) and judged after it: each against the ray-traced references
//! (point-sampled and anti-aliased), as drawn and as exact geometry, whole and per
//! object; `psnr.csv`, the worst frame and each object's worst frame ([`worst`])
//! written.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};

use relief_client::manager::ShownTexture;
use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::scene::Scene;
use relief_lab::image_error::{compare, object_psnr};
use relief_render::gbuffer::GBuffer;
use relief_render::geometry::{is_cheap, render_geometry};
use relief_trace::{ANTIALIASED_SAMPLES, SceneTracer, render_reference};

use super::worst;
use crate::progress;

/// The image error of the compared frames, each as drawn and as all geometry.
#[derive(Default)]
pub(super) struct Judged {
    /// Against the point-sampled reference, over the pixels both show …
    pub(super) psnr: Vec<f64>,
    /// … over every pixel either shows, and the fraction only one does.
    pub(super) psnr_whole: Vec<f64>,
    pub(super) hole_frac: Vec<f64>,
    pub(super) psnr_aa: Vec<f64>,
    pub(super) geometry_psnr_aa: Vec<f64>,
    /// Per object that may be an impostor, in each frame where it covers at least
    /// [`MIN_JUDGED_OBJECT_PIXELS`] of the reference: its own PSNR ([`object_psnr`])
    /// against the anti-aliased reference, as drawn and as exact geometry (`psnr.csv`
    /// has every frame's) …
    pub(super) by_object: BTreeMap<String, Vec<f64>>,
    pub(super) geometry_by_object: BTreeMap<String, Vec<f64>>,
    /// … and the first minus the second.
    pub(super) gap_by_object: BTreeMap<String, Vec<f64>>,
}

/// The fewest pixels of the reference an object must cover for its frame to count in
/// the summary's figures by object: on fewer (an object cut by the frame's edge), one
/// misplaced texel moves the figure by many dB (the sphere at 9.6 dB against
/// geometry's 34.2 on a sliver at the edge; the rock at 12.4 dB on a frame where the
/// reference showed none of it and the impostor one pixel, with no figure for
/// geometry to set beside it).
pub(super) const MIN_JUDGED_OBJECT_PIXELS: usize = 400;

/// What the flight keeps to be judged after it, within a memory budget: every
/// `every`-th frame, from `--reference-every` on. Past the budget, every other kept one
/// is let go and frames are kept half as often from then on, so that those kept stay
/// evenly spread (frames `0, 2K, 4K, …`). (One frame larger than the whole budget is
/// kept all the same.)
pub(super) struct KeptForJudging<T> {
    every: u32,
    budget: usize,
    item_bytes: usize,
    kept: Vec<T>,
}

impl<T> KeptForJudging<T> {
    /// Every `every`-th (0: none) of items `item_bytes` each, within `budget` bytes.
    pub(super) fn new(every: u32, item_bytes: usize, budget: usize) -> Self {
        KeptForJudging {
            every,
            budget,
            item_bytes: item_bytes.max(1),
            kept: Vec::new(),
        }
    }

    /// Whether frame `index` of the flight is to be kept.
    pub(super) fn wants(&self, index: u32) -> bool {
        self.every > 0 && index.is_multiple_of(self.every)
    }

    /// Keeps `item`, a frame [`KeptForJudging::wants`], thinning past the budget.
    pub(super) fn keep(&mut self, item: T) {
        self.kept.push(item);
        if self.kept.len() * self.item_bytes > self.budget {
            let mut k = 0;
            self.kept.retain(|_| {
                k += 1;
                k % 2 == 1
            });
            self.every = self.every.saturating_mul(2);
        }
    }

    /// Every how many frames those kept were kept, in the end.
    pub(super) fn every(&self) -> u32 {
        self.every
    }

    /// Those kept, in the order they came.
    pub(super) fn into_kept(self) -> Vec<T> {
        self.kept
    }
}

/// A frame kept to be judged after the flight.
pub(super) struct Compared {
    pub(super) path_frame: u32,
    pub(super) camera: Camera,
    pub(super) image: Frame,
    /// How each object was drawn ([`Flown::shown`](relief_client::flight::Flown::shown)).
    pub(super) shown: Vec<Option<ShownTexture>>,
}

/// Compares each kept frame with the ray-traced references; writes `psnr.csv` (with,
/// per object that may be an impostor, how it was drawn — the texture's turn and
/// distance, the level drawn, its predicted errors, its partner — empty for geometry),
/// the worst frame with its reference, and each object's worst paired frame
/// ([`worst::side_by_side`]) into `out`.
pub(super) fn judge(scene: &Scene, compared: &[Compared], out: &Path) -> Result<Judged> {
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
    let mut log = String::from("frame,psnr_db,psnr_whole_db,hole_frac,psnr_aa_db,geometry_psnr_aa_db");
    for (_, name) in &candidates {
        let name = column(name);
        log.push_str(&format!(
            ",psnr_aa_db_{name},geometry_psnr_aa_db_{name},pixels_{name},drawn_px_{name},turn_deg_{name},distance_ratio_{name},texel_px_{name},edge_{name},level_{name},growth_px_{name},band_px_{name},unseen_pct_{name},partner_turn_deg_{name}"
        ));
    }
    log.push('\n');
    let mut worst = f64::INFINITY;
    // Each object's lowest paired gap so far, as a picture (`worst::side_by_side`).
    let mut worst_pictures = BTreeMap::new();
    for Compared {
        path_frame: frame,
        camera,
        image,
        shown,
    } in compared
    {
        let reference = render_reference(&tracer, camera, 1);
        let antialiased = render_reference(&tracer, camera, ANTIALIASED_SAMPLES);
        let geometry = render_geometry(scene, camera, &mut GBuffer::new(camera.width, camera.height));
        let error = compare(image, &reference, None);
        let p = error.psnr_db;
        let p_aa = compare(image, &antialiased, None).psnr_db;
        let floor = compare(&geometry, &antialiased, None).psnr_db;
        log.push_str(&format!(
            "{frame},{p:.3},{:.3},{:.5},{p_aa:.3},{floor:.3}",
            error.psnr_whole_db, error.hole_frac
        ));
        for &(k, name) in &candidates {
            let own = object_psnr(image, &antialiased, k);
            let own_floor = object_psnr(&geometry, &antialiased, k);
            let covered = antialiased.object.iter().filter(|&&o| o == k).count();
            if let (Some(a), Some(b)) = (own, own_floor)
                && covered >= MIN_JUDGED_OBJECT_PIXELS
            {
                // The impostor's and geometry's figures over the same frames, so that
                // their minima and medians compare.
                judged.by_object.entry(name.to_string()).or_default().push(a);
                judged
                    .geometry_by_object
                    .entry(name.to_string())
                    .or_default()
                    .push(b);
                let gaps = judged.gap_by_object.entry(name.to_string()).or_default();
                if (a - b).is_finite()
                    && gaps.iter().all(|&g| g > a - b)
                    && let Some(picture) = worst::side_by_side([image, &antialiased, &geometry], k)
                {
                    worst_pictures.insert(name, picture);
                }
                gaps.push(a - b);
            }
            for value in [own, own_floor] {
                log.push(',');
                if let Some(v) = value {
                    log.push_str(&format!("{v:.3}"));
                }
            }
            let drawn = image.object.iter().filter(|&&o| o == k).count();
            log.push_str(&format!(",{covered},{drawn}"));
            let how = shown.get(k as usize).copied().flatten();
            let fields = how.map(|s| {
                (
                    (s.turn_deg, s.distance_ratio),
                    s.texel_pixels,
                    (s.edge, s.level),
                    s.growth_pixels,
                    (s.band_pixels, s.unseen_percent),
                    s.partner_turn_deg,
                )
            });
            match fields {
                Some(((turn, ratio), texel, (edge, level), growth, (band, unseen), partner)) => {
                    log.push_str(&format!(
                        ",{turn:.1},{ratio:.3},{texel:.2},{edge},{level},{growth:.2},{band:.2},{unseen:.2},"
                    ));
                    if let Some(p) = partner {
                        log.push_str(&format!("{p:.1}"));
                    }
                }
                None => log.push_str(",,,,,,,,,"),
            }
        }
        log.push('\n');
        if p < worst {
            worst = p;
            image.save_png(&out.join("worst_frame.png"))?;
            reference.save_png(&out.join("worst_frame_reference.png"))?;
        }
        judged.psnr.push(p);
        judged.psnr_whole.push(error.psnr_whole_db);
        judged.hole_frac.push(error.hole_frac);
        judged.psnr_aa.push(p_aa);
        judged.geometry_psnr_aa.push(floor);
        bar.inc(1);
    }
    bar.finish_and_clear();
    std::fs::write(out.join("psnr.csv"), log).context("writing psnr.csv")?;
    for (name, picture) in worst_pictures {
        worst::save(out, &column(name), &picture)?;
    }
    Ok(judged)
}

/// `figure` (a finite minimum, median, …) of each object's values, for the objects that
/// have one.
pub(super) fn by_object(
    values: &BTreeMap<String, Vec<f64>>,
    figure: fn(&[f64]) -> Option<f64>,
) -> BTreeMap<String, f64> {
    values
        .iter()
        .filter_map(|(name, values)| Some((name.clone(), figure(values)?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Past the budget, those kept are thinned to every other one and later frames are
    /// kept half as often: evenly spread, every `2^n·K`-th, within the budget.
    #[test]
    fn frames_kept_for_judging_stay_within_the_budget_evenly_spread() {
        // (Four fit in 40 bytes; the fifth passes them.)
        let mut kept = KeptForJudging::new(3, 10, 40);
        for index in 0..100 {
            if kept.wants(index) {
                kept.keep(index);
            }
        }
        // (0, 3, 6, 9, 12: past 40 bytes, thinned to 0, 6, 12; then 0, 12, 24; 0, 24, 48;
        // 0, 48, 96.)
        assert_eq!(kept.every(), 48);
        assert_eq!(kept.into_kept(), [0, 48, 96]);
        let none = KeptForJudging::<u32>::new(0, 10, 40);
        assert!(!(0..10).any(|index| none.wants(index)));
    }
}
