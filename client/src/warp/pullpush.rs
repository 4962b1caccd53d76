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
use wide::f32x8;

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

/// A pixel as the fill averages it, in eight float lanes: depth, albedo (3), encoded
/// normal (3), and 1 — so one weighted sum of lanes sums the weights as well. The coarse
/// levels are kept this way (32 bytes a pixel, but a quarter of the pixels or fewer):
/// they are read four times per finer pixel, and unpacking bytes each time cost more
/// than the memory.
pub type Lanes = f32x8;

/// An empty pixel in lanes.
const EMPTY_LANES: Lanes = f32x8::new([f32::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);

/// What a layer can hold: the finest level's [`Splat`]s or a coarse level's [`Lanes`].
pub trait Pixel: Copy + Send + Sync {
    /// An empty pixel.
    const EMPTY: Self;
    /// View depth; `INFINITY` when empty.
    fn depth(&self) -> f32;
    /// The pixel in lanes.
    fn lanes(&self) -> Lanes;
    /// The pixel of an average in lanes.
    fn from_lanes(lanes: Lanes) -> Self;
}

impl Pixel for Splat {
    const EMPTY: Splat = Splat::EMPTY;

    #[inline(always)]
    fn depth(&self) -> f32 {
        self.depth
    }

    #[inline(always)]
    fn lanes(&self) -> Lanes {
        let ([r, g, b], [x, y, z]) = (self.albedo, self.normal);
        let f = |c: u8| c as f32;
        f32x8::new([self.depth, f(r), f(g), f(b), f(x), f(y), f(z), 1.0])
    }

    /// Rounds the attributes to bytes (to nearest: `round_int`'s conversion).
    #[inline(always)]
    fn from_lanes(lanes: Lanes) -> Splat {
        let depth = lanes.as_array()[0];
        let q = lanes.round_int().to_array();
        // (Bounded: a NaN lane converts to i32::MIN.)
        let byte = |k: usize| q[k].clamp(0, 255) as u8;
        Splat {
            depth,
            albedo: [byte(1), byte(2), byte(3)],
            normal: [byte(4), byte(5), byte(6)],
        }
    }
}

impl Pixel for Lanes {
    const EMPTY: Lanes = EMPTY_LANES;

    #[inline(always)]
    fn depth(&self) -> f32 {
        self.as_array()[0]
    }

    #[inline(always)]
    fn lanes(&self) -> Lanes {
        *self
    }

    #[inline(always)]
    fn from_lanes(lanes: Lanes) -> Lanes {
        lanes
    }
}

/// A `width × height` image of splats (or, inside the fill, of a coarse level's lanes).
#[derive(Debug, Clone, PartialEq)]
pub struct Layer<P = Splat> {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<P>,
}

impl Layer {
    pub fn new(width: usize, height: usize) -> Layer {
        Layer::empty(width, height)
    }
}

impl<P: Pixel> Layer<P> {
    fn empty(width: usize, height: usize) -> Layer<P> {
        Layer {
            width,
            height,
            pixels: vec![P::EMPTY; width * height],
        }
    }

    #[inline]
    fn row(&self, y: usize) -> &[P] {
        &self.pixels[y * self.width..(y + 1) * self.width]
    }
}

/// The depth range, at one level of the pyramid, that still counts as one surface:
/// `per_depth · depth + constant` (a pixel's footprint grows with its depth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    pub per_depth: f32,
    pub constant: f32,
}

impl Tolerance {
    /// The range at `depth`.
    #[inline(always)]
    pub fn at(&self, depth: f32) -> f32 {
        depth.mul_add(self.per_depth, self.constant)
    }
}

/// The nearest depth among `candidates` (`INFINITY` when all are empty).
#[inline(always)]
fn nearest<P: Pixel>(candidates: &[(f32, P)]) -> f32 {
    candidates
        .iter()
        .map(|(_, p)| p.depth())
        .fold(f32::INFINITY, f32::min)
}

/// Averages the front-most group of `candidates` (positive weights, pixels): those
/// within `tolerance` of the nearest. Empty lanes when all are empty.
#[inline(always)]
pub(crate) fn front_average<P: Pixel>(candidates: &[(f32, P)], tolerance: Tolerance) -> Lanes {
    let nearest = nearest(candidates);
    if nearest == f32::INFINITY {
        return EMPTY_LANES;
    }
    let limit = nearest + tolerance.at(nearest);
    let mut sum = f32x8::ZERO;
    for (w, p) in candidates {
        if p.depth() <= limit {
            sum = p.lanes().mul_add(f32x8::splat(*w), sum);
        }
    }
    // The last lane summed the weights.
    sum * f32x8::splat(1.0 / sum.as_array()[7])
}

/// Fills the holes of `layer` using at most `levels` coarser levels; `tolerance(level)`
/// says what counts as one surface at a level.
pub fn fill(layer: &mut Layer, levels: usize, tolerance: impl Fn(usize) -> Tolerance) {
    if layer.width == 0 || layer.height == 0 {
        return;
    }
    // Analysis.
    let mut pyramid: Vec<Layer<Lanes>> = Vec::with_capacity(levels);
    for level in 0..levels {
        let (w, h) = pyramid
            .last()
            .map_or((layer.width, layer.height), |l| (l.width, l.height));
        if w <= 1 && h <= 1 {
            break;
        }
        let coarse = match pyramid.last() {
            Some(fine) => analyse(fine, tolerance(level)),
            None => analyse(layer, tolerance(level)),
        };
        pyramid.push(coarse);
    }
    // Synthesis, coarsest first.
    for level in (0..pyramid.len()).rev() {
        let (upper, lower) = pyramid.split_at_mut(level);
        let (here, above) = (tolerance(level), tolerance(level + 1));
        match upper.last_mut() {
            Some(fine) => synthesise(fine, &lower[0], here, above),
            None => synthesise(layer, &lower[0], here, above),
        }
    }
}

/// A sample position along one axis: two (index, weight) taps. A tap past the border
/// is clamped to the edge pixel (which then counts twice: the same average as leaving
/// it out), so every weight is positive.
type Taps = [(usize, f32); 2];

/// The 2×2 pixels at columns `x` of two `rows`, each weighted by its row's and its
/// column's weight.
#[inline(always)]
fn gather<P: Pixel>(
    [(r0, wy0), (r1, wy1)]: [(&[P], f32); 2],
    &[(x0, wx0), (x1, wx1)]: &Taps,
) -> [(f32, P); 4] {
    [
        (wy0 * wx0, r0[x0]),
        (wy0 * wx1, r0[x1]),
        (wy1 * wx0, r1[x0]),
        (wy1 * wx1, r1[x1]),
    ]
}

/// The coarse level: each pixel the front-most average of its 2×2 children.
fn analyse<P: Pixel>(fine: &Layer<P>, tolerance: Tolerance) -> Layer<Lanes> {
    let (w, h) = (fine.width.div_ceil(2), fine.height.div_ceil(2));
    let children = |n: usize, fine: usize| -> Vec<Taps> {
        (0..n)
            .map(|x| [(2 * x, 1.0), ((2 * x + 1).min(fine - 1), 1.0)])
            .collect()
    };
    let (xs, ys) = (children(w, fine.width), children(h, fine.height));
    let mut coarse = Layer::empty(w, h);
    coarse
        .pixels
        .par_chunks_mut(w)
        .zip(&ys)
        .for_each(|(row, &[(y0, wy0), (y1, wy1)])| {
            let rows = [(fine.row(y0), wy0), (fine.row(y1), wy1)];
            for (out, x) in row.iter_mut().zip(&xs) {
                *out = front_average(&gather(rows, x), tolerance);
            }
        });
    coarse
}

/// Fine pixel x's centre falls at coarse coordinate x/2 − 1/4: the taps of `n` fine
/// pixels over `coarse` coarse ones, weights 3/4 and 1/4.
fn upsampling_taps(n: usize, coarse: usize) -> Vec<Taps> {
    (0..n)
        .map(|x| {
            let c = x as f32 * 0.5 - 0.25;
            let (i, f) = (c.floor(), c - c.floor());
            let tap = |j: f32, w: f32| ((j.max(0.0) as usize).min(coarse - 1), w);
            [tap(i, 1.0 - f), tap(i + 1.0, f)]
        })
        .collect()
}

/// One fine pixel from the four coarse `candidates` around it: an empty pixel takes
/// their front-most blend, and a valid pixel well behind that blend is replaced by it.
/// `here` is the fine level's surface tolerance, `above` the coarse level's.
#[inline(always)]
fn synthesise_pixel<P: Pixel>(
    pixel: &mut P,
    candidates: &[(f32, Lanes); 4],
    here: Tolerance,
    above: Tolerance,
) {
    let depth = pixel.depth();
    let valid = depth < f32::INFINITY;
    // A valid pixel in front of every coarse candidate stays as it is: skip the blend.
    if valid {
        let nearest = nearest(candidates);
        if depth <= nearest + here.at(nearest.min(depth)) {
            return;
        }
    }
    let blend = front_average(candidates, above);
    let blend_depth = blend.as_array()[0];
    if blend_depth < f32::INFINITY && (!valid || depth > blend_depth + here.at(blend_depth)) {
        *pixel = P::from_lanes(blend);
    }
}

/// Fills a level from the one above it, pixel by pixel ([`synthesise_pixel`]).
fn synthesise<P: Pixel>(fine: &mut Layer<P>, coarse: &Layer<Lanes>, here: Tolerance, above: Tolerance) {
    let xs = upsampling_taps(fine.width, coarse.width);
    let ys = upsampling_taps(fine.height, coarse.height);
    let width = fine.width;
    fine.pixels
        .par_chunks_mut(width)
        .zip(&ys)
        .for_each(|(row, &[(y0, wy0), (y1, wy1)])| {
            let rows = [(coarse.row(y0), wy0), (coarse.row(y1), wy1)];
            for (pixel, x) in row.iter_mut().zip(&xs) {
                synthesise_pixel(pixel, &gather(rows, x), here, above);
            }
        });
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
        fill(&mut layer, 1, |_| Tolerance {
            per_depth: 0.0,
            constant: 0.1,
        });
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
        fill(&mut layer, 2, |_| Tolerance {
            per_depth: 0.0,
            constant: 0.5,
        });
        let p = layer.pixels[3 * 8 + 3];
        assert!((p.depth - 1.0).abs() < 1e-5 && p.albedo == [51; 3], "{p:?}");
    }
}
