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

use rayon::prelude::*;

/// One pixel of a layer being reconstructed. Attributes stay in the texture's 8-bit
/// encoding: 12 bytes a pixel, so a 1280×720 layer is 11 MB — the fill is bound by
/// memory traffic, and float attributes (32 bytes) made it 2–3× slower.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Splat {
    /// View depth; `INFINITY` marks an empty pixel.
    pub depth: f32,
    /// Albedo, 8 bits per channel.
    pub albedo: [u8; 3],
    /// Normal, encoded as the texture stores it ([`relief_core::relief::encode_normal`]);
    /// averaging encoded normals averages the vectors.
    pub normal: [u8; 3],
}

impl Splat {
    pub const EMPTY: Splat = Splat {
        depth: f32::INFINITY,
        albedo: [0; 3],
        normal: [0; 3],
    };

    #[inline(always)]
    pub fn is_valid(&self) -> bool {
        self.depth < f32::INFINITY
    }
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

/// The nearest depth among `candidates` (`INFINITY` when all are empty).
#[inline(always)]
fn nearest(candidates: &[(f32, Splat)]) -> f32 {
    candidates
        .iter()
        .map(|(_, s)| s.depth)
        .fold(f32::INFINITY, f32::min)
}

/// Averages the front-most group of `candidates` (positive weights, splats): those
/// within `tolerance(depth)` of the nearest.
#[inline]
pub(crate) fn front_average(candidates: &[(f32, Splat)], tolerance: impl Fn(f32) -> f32) -> Splat {
    let nearest = nearest(candidates);
    if nearest == f32::INFINITY {
        return Splat::EMPTY;
    }
    let limit = nearest + tolerance(nearest);
    let (mut weight, mut depth) = (0.0, 0.0);
    let mut attributes = [0f32; 6];
    for (w, s) in candidates {
        if s.depth <= limit {
            weight += w;
            depth += w * s.depth;
            let [r, g, b] = s.albedo;
            let [x, y, z] = s.normal;
            for (sum, c) in attributes.iter_mut().zip([r, g, b, x, y, z]) {
                *sum += w * c as f32;
            }
        }
    }
    let inv = 1.0 / weight;
    let byte = |k: usize| super::round_small(attributes[k] * inv) as u8;
    Splat {
        depth: depth * inv,
        albedo: [byte(0), byte(1), byte(2)],
        normal: [byte(3), byte(4), byte(5)],
    }
}

/// Fills the holes of `layer` using at most `levels` coarser levels. `tolerance(depth,
/// level)` is the depth range, at a level, that still counts as one surface.
pub fn fill(layer: &mut Layer, levels: usize, tolerance: impl Fn(f32, usize) -> f32 + Sync) {
    if layer.width == 0 || layer.height == 0 {
        return;
    }
    // Analysis.
    let mut pyramid: Vec<Layer> = Vec::with_capacity(levels);
    for level in 0..levels {
        let fine = pyramid.last().unwrap_or(layer);
        if fine.width <= 1 && fine.height <= 1 {
            break;
        }
        pyramid.push(analyse(fine, |d| tolerance(d, level)));
    }
    // Synthesis, coarsest first.
    for level in (0..pyramid.len()).rev() {
        let (upper, lower) = pyramid.split_at_mut(level);
        let fine: &mut Layer = match upper.last_mut() {
            Some(l) => l,
            None => &mut *layer,
        };
        synthesise(
            fine,
            &lower[0],
            |d| tolerance(d, level),
            |d| tolerance(d, level + 1),
        );
    }
}

/// A sample position along one axis: two (index, weight) taps. A tap past the border
/// is clamped to the edge pixel (which then counts twice: the same average as leaving
/// it out), so every weight is positive.
type Taps = [(usize, f32); 2];

/// The 2×2 pixels at columns `x` of two `rows`, each weighted by its row's and its
/// column's weight.
#[inline(always)]
fn gather([(r0, wy0), (r1, wy1)]: [(&[Splat], f32); 2], &[(x0, wx0), (x1, wx1)]: &Taps) -> [(f32, Splat); 4] {
    [
        (wy0 * wx0, r0[x0]),
        (wy0 * wx1, r0[x1]),
        (wy1 * wx0, r1[x0]),
        (wy1 * wx1, r1[x1]),
    ]
}

/// The coarse level: each pixel the front-most average of its 2×2 children.
fn analyse(fine: &Layer, tolerance: impl Fn(f32) -> f32 + Sync) -> Layer {
    let (w, h) = (fine.width.div_ceil(2), fine.height.div_ceil(2));
    let children = |n: usize, fine: usize| -> Vec<Taps> {
        (0..n)
            .map(|x| [(2 * x, 1.0), ((2 * x + 1).min(fine - 1), 1.0)])
            .collect()
    };
    let (xs, ys) = (children(w, fine.width), children(h, fine.height));
    let mut coarse = Layer::new(w, h);
    coarse
        .pixels
        .par_chunks_mut(w)
        .zip(&ys)
        .for_each(|(row, &[(y0, wy0), (y1, wy1)])| {
            let rows = [(fine.row(y0), wy0), (fine.row(y1), wy1)];
            for (out, x) in row.iter_mut().zip(&xs) {
                *out = front_average(&gather(rows, x), &tolerance);
            }
        });
    coarse
}

/// Fills `fine` from the coarse level above it: an empty pixel takes the bilinear blend
/// of the four coarse pixels around its centre (front-most group), and a valid pixel
/// well behind that blend is replaced by it. `here` is this level's surface tolerance,
/// `above` the coarse level's.
fn synthesise(
    fine: &mut Layer,
    coarse: &Layer,
    here: impl Fn(f32) -> f32 + Sync,
    above: impl Fn(f32) -> f32 + Sync,
) {
    // Fine pixel x's centre falls at coarse coordinate x/2 − 1/4: weights 3/4 and 1/4.
    let taps = |n: usize, coarse: usize| -> Vec<Taps> {
        (0..n)
            .map(|x| {
                let c = x as f32 * 0.5 - 0.25;
                let (i, f) = (c.floor(), c - c.floor());
                let tap = |j: f32, w: f32| ((j.max(0.0) as usize).min(coarse - 1), w);
                [tap(i, 1.0 - f), tap(i + 1.0, f)]
            })
            .collect()
    };
    let (xs, ys) = (taps(fine.width, coarse.width), taps(fine.height, coarse.height));
    let width = fine.width;
    fine.pixels
        .par_chunks_mut(width)
        .zip(&ys)
        .for_each(|(row, &[(y0, wy0), (y1, wy1)])| {
            let rows = [(coarse.row(y0), wy0), (coarse.row(y1), wy1)];
            for (pixel, x) in row.iter_mut().zip(&xs) {
                let candidates = gather(rows, x);
                // A valid pixel in front of every coarse candidate stays as it is: skip
                // the blend.
                if pixel.is_valid() {
                    let nearest = nearest(&candidates);
                    if pixel.depth <= nearest + here(nearest.min(pixel.depth)) {
                        continue;
                    }
                }
                let blend = front_average(&candidates, &above);
                if blend.is_valid() && (!pixel.is_valid() || pixel.depth > blend.depth + here(blend.depth)) {
                    *pixel = blend;
                }
            }
        });
}

impl Layer {
    #[inline]
    fn row(&self, y: usize) -> &[Splat] {
        &self.pixels[y * self.width..(y + 1) * self.width]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn splat(depth: f32, albedo: u8) -> Splat {
        Splat {
            depth,
            albedo: [albedo; 3],
            normal: [128, 128, 255],
        }
    }

    #[test]
    fn fills_a_sparse_grid_without_growing_far() {
        // Samples every other pixel of a 16×16 square in a 32×32 layer.
        let mut layer = Layer::new(32, 32);
        for y in (8..24).step_by(2) {
            for x in (8..24).step_by(2) {
                layer.pixels[y * 32 + x] = splat(5.0, 128);
            }
        }
        fill(&mut layer, 1, |_, _| 0.1);
        for y in 8..23 {
            for x in 8..23 {
                assert!(layer.pixels[y * 32 + x].is_valid(), "hole left at {x},{y}");
            }
        }
        assert!(
            !layer.pixels[2 * 32 + 2].is_valid(),
            "filled far outside the samples"
        );
    }

    #[test]
    fn background_seen_through_a_hole_is_replaced() {
        // Front surface at depth 1 with a one-pixel hole showing a sample at depth 9.
        let mut layer = Layer::new(8, 8);
        for k in 0..64 {
            layer.pixels[k] = splat(1.0, 51);
        }
        layer.pixels[3 * 8 + 3] = splat(9.0, 230);
        fill(&mut layer, 2, |_, _| 0.5);
        let p = layer.pixels[3 * 8 + 3];
        assert!((p.depth - 1.0).abs() < 1e-5 && p.albedo == [51; 3], "{p:?}");
    }
}
