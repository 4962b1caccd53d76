//! Pyramid analysis–synthesis ("pull–push") hole filling with occlusion (Marroquim
//! ch. 4).
//!
//! Analysis builds each coarser level from 2×2 finer pixels, averaging only the valid
//! ones whose depth is within a tolerance of the front-most (so a background sample seen
//! through a hole in the front surface does not bleed in). Synthesis goes back down:
//! an empty pixel takes the bilinear blend of the coarser level's valid pixels nearest
//! to it (again only the front-most group), and a valid pixel well behind that blend —
//! covered by the front surface, but seen through a hole — is replaced by it. The
//! number of levels bounds how far the fill reaches, so an impostor grows by at most
//! about one sample spacing past its silhouette.

use glam::Vec3;
use rayon::prelude::*;

/// One pixel of a layer being reconstructed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Splat {
    /// View depth; meaningful only when `valid`.
    pub depth: f32,
    pub albedo: Vec3,
    pub normal: Vec3,
    pub valid: bool,
}

impl Splat {
    pub const EMPTY: Splat = Splat {
        depth: f32::INFINITY,
        albedo: Vec3::ZERO,
        normal: Vec3::ZERO,
        valid: false,
    };
}

/// A `width × height` image of splats.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Splat>,
}

impl Layer {
    pub fn new(width: usize, height: usize) -> Layer {
        Layer {
            width,
            height,
            pixels: vec![Splat::EMPTY; width * height],
        }
    }
}

/// Averages the front-most group of `candidates` (weights, splats): those within
/// `tolerance(depth)` of the nearest.
#[inline]
pub(crate) fn front_average(candidates: &[(f32, Splat)], tolerance: impl Fn(f32) -> f32) -> Splat {
    let nearest = candidates
        .iter()
        .filter(|(w, s)| s.valid && *w > 0.0)
        .map(|(_, s)| s.depth)
        .fold(f32::INFINITY, f32::min);
    if nearest == f32::INFINITY {
        return Splat::EMPTY;
    }
    let limit = nearest + tolerance(nearest);
    let (mut weight, mut depth, mut albedo, mut normal) = (0.0, 0.0, Vec3::ZERO, Vec3::ZERO);
    for (w, s) in candidates {
        if s.valid && *w > 0.0 && s.depth <= limit {
            weight += w;
            depth += w * s.depth;
            albedo += *w * s.albedo;
            normal += *w * s.normal;
        }
    }
    Splat {
        depth: depth / weight,
        albedo: albedo / weight,
        normal: normal / weight,
        valid: true,
    }
}

/// Fills the holes of `layer` using at most `levels` coarser levels. `tolerance(depth,
/// level)` is the depth range, at a level, that still counts as one surface.
pub fn fill(layer: &mut Layer, levels: usize, tolerance: impl Fn(f32, usize) -> f32 + Sync) {
    // Analysis.
    let mut pyramid: Vec<Layer> = Vec::with_capacity(levels);
    for level in 0..levels {
        let fine = pyramid.last().unwrap_or(layer);
        if fine.width <= 1 && fine.height <= 1 {
            break;
        }
        let (w, h) = (fine.width.div_ceil(2), fine.height.div_ceil(2));
        let mut coarse = Layer::new(w, h);
        coarse.pixels.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let mut children = [(0.0f32, Splat::EMPTY); 4];
                for (k, (dx, dy)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                    let (fx, fy) = (2 * x + dx, 2 * y + dy);
                    if fx < fine.width && fy < fine.height {
                        children[k] = (1.0, fine.pixels[fy * fine.width + fx]);
                    }
                }
                *out = front_average(&children, |d| tolerance(d, level));
            }
        });
        pyramid.push(coarse);
    }
    // Synthesis, coarsest first.
    for level in (0..pyramid.len()).rev() {
        let (upper, lower) = pyramid.split_at_mut(level);
        let coarse = &lower[0];
        let fine: &mut Layer = match upper.last_mut() {
            Some(l) => l,
            None => &mut *layer,
        };
        let fine_width = fine.width;
        fine.pixels
            .par_chunks_mut(fine_width)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, pixel) in row.iter_mut().enumerate() {
                    // The four coarse pixels around this one's centre, bilinear weights.
                    let cx = (x as f32 + 0.5) / 2.0 - 0.5;
                    let cy = (y as f32 + 0.5) / 2.0 - 0.5;
                    let (ix, iy) = (cx.floor(), cy.floor());
                    let (fx, fy) = (cx - ix, cy - iy);
                    let mut candidates = [(0.0f32, Splat::EMPTY); 4];
                    for (k, (dx, dy, w)) in [
                        (0, 0, (1.0 - fx) * (1.0 - fy)),
                        (1, 0, fx * (1.0 - fy)),
                        (0, 1, (1.0 - fx) * fy),
                        (1, 1, fx * fy),
                    ]
                    .into_iter()
                    .enumerate()
                    {
                        let (qx, qy) = (ix as i64 + dx, iy as i64 + dy);
                        if qx >= 0 && qy >= 0 && (qx as usize) < coarse.width && (qy as usize) < coarse.height
                        {
                            candidates[k] = (w, coarse.pixels[qy as usize * coarse.width + qx as usize]);
                        }
                    }
                    // A valid pixel in front of every coarse candidate stays as it is:
                    // skip the blend.
                    if pixel.valid {
                        let nearest = candidates
                            .iter()
                            .filter(|(w, c)| c.valid && *w > 0.0)
                            .map(|(_, c)| c.depth)
                            .fold(f32::INFINITY, f32::min);
                        if pixel.depth <= nearest + tolerance(nearest.min(pixel.depth), level) {
                            continue;
                        }
                    }
                    let blend = front_average(&candidates, |d| tolerance(d, level + 1));
                    if !blend.valid {
                        continue;
                    }
                    let occluded = pixel.valid && pixel.depth > blend.depth + tolerance(blend.depth, level);
                    if !pixel.valid || occluded {
                        *pixel = blend;
                    }
                }
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn splat(depth: f32, albedo: f32) -> Splat {
        Splat {
            depth,
            albedo: Vec3::splat(albedo),
            normal: Vec3::Z,
            valid: true,
        }
    }

    #[test]
    fn fills_a_sparse_grid_without_growing_far() {
        // Samples every other pixel of a 16×16 square in a 32×32 layer.
        let mut layer = Layer::new(32, 32);
        for y in (8..24).step_by(2) {
            for x in (8..24).step_by(2) {
                layer.pixels[y * 32 + x] = splat(5.0, 0.5);
            }
        }
        fill(&mut layer, 1, |_, _| 0.1);
        for y in 8..23 {
            for x in 8..23 {
                assert!(layer.pixels[y * 32 + x].valid, "hole left at {x},{y}");
            }
        }
        assert!(!layer.pixels[2 * 32 + 2].valid, "filled far outside the samples");
    }

    #[test]
    fn background_seen_through_a_hole_is_replaced() {
        // Front surface at depth 1 with a one-pixel hole showing a sample at depth 9.
        let mut layer = Layer::new(8, 8);
        for k in 0..64 {
            layer.pixels[k] = splat(1.0, 0.2);
        }
        layer.pixels[3 * 8 + 3] = splat(9.0, 0.9);
        fill(&mut layer, 2, |_, _| 0.5);
        let p = layer.pixels[3 * 8 + 3];
        assert!(
            (p.depth - 1.0).abs() < 1e-5 && (p.albedo.x - 0.2).abs() < 1e-5,
            "{p:?}"
        );
    }
}
