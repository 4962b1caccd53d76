//! Pyramid analysis–synthesis ("pull–push") hole filling with occlusion (Marroquim
//! ch. 4).
//!
//! Analysis builds each coarser level from 2×2 finer pixels, averaging only the valid
//! ones whose depth is within a margin of the front-most (so a background sample seen
//! through a hole in the front surface does not bleed in). Synthesis goes back down:
//! an empty pixel takes the bilinear blend of the coarser level's valid pixels nearest
//! to it (again only the front-most group), and a valid pixel well behind that blend —
//! covered by the front surface, but seen through a hole — is replaced by it. The
//! number of levels bounds how far the fill reaches, so an impostor grows by at most
//! about one sample spacing past its silhouette.

use rayon::prelude::*;
use wide::{f32x8, i16x8, u8x16};

use relief_render::EMPTY_DEPTH;

/// One pixel of a layer being reconstructed. Attributes stay in the texture's 8-bit
/// encoding: 12 bytes a pixel, so a 1280×720 layer is 11 MB — the fill is bound by
/// memory traffic, and float attributes (32 bytes) made it 2–3× slower.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Splat {
    /// View depth; [`EMPTY_DEPTH`] marks an empty pixel.
    pub depth: f32,
    /// Albedo, 8 bits per channel.
    pub albedo: [u8; 3],
    /// Normal, encoded as the texture stores it ([`relief_core::relief::encode_normal_rgb8`]);
    /// averaging encoded normals averages the vectors.
    pub normal: [u8; 3],
}

impl Splat {
    pub const EMPTY: Splat = Splat {
        depth: EMPTY_DEPTH,
        albedo: [0; 3],
        normal: [0; 3],
    };

    #[inline(always)]
    pub fn is_valid(&self) -> bool {
        self.depth < EMPTY_DEPTH
    }
}

/// A pixel as the fill averages it, in eight float lanes: depth, albedo (3), encoded
/// normal (3), and 1 — so one weighted sum of lanes sums the weights as well. The coarse
/// levels are kept this way (32 bytes a pixel, but a quarter of the pixels or fewer):
/// every finer pixel's blend reads four, and unpacking bytes each time cost more than
/// the memory.
pub type Lanes = f32x8;

/// An empty pixel in lanes.
const EMPTY_LANES: Lanes = f32x8::new([EMPTY_DEPTH, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);

/// What a layer can hold: the finest level's [`Splat`]s or a coarse level's [`Lanes`].
pub trait Pixel: Copy + Send + Sync {
    /// An empty pixel.
    const EMPTY: Self;
    /// View depth; [`EMPTY_DEPTH`] when empty.
    fn depth(&self) -> f32;
    /// The pixel in lanes.
    fn lanes(&self) -> Lanes;
    /// The pixel of an average in lanes.
    fn from_lanes(lanes: Lanes) -> Self;
    /// The pixel in lanes if its depth is at most `limit`, else zeros.
    fn lanes_within(&self, limit: f32) -> Lanes;
}

impl Pixel for Splat {
    const EMPTY: Splat = Splat::EMPTY;

    /// (A branch: most pixels left out are empty, and converting them costs more.)
    #[inline(always)]
    fn lanes_within(&self, limit: f32) -> Lanes {
        if self.depth <= limit {
            self.lanes()
        } else {
            f32x8::ZERO
        }
    }

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

    /// Rounds the attributes to bytes (to nearest; ties to even on x86), clamped to
    /// 0..=255.
    #[inline(always)]
    fn from_lanes(lanes: Lanes) -> Splat {
        let depth = lanes.as_array()[0];
        // Two saturating packs clamp as they narrow (i32 → i16 → u8), as vectors. (The
        // plain conversion: a NaN or out-of-range lane converts to i32::MIN, hence 0.)
        let q16 = i16x8::from_i32x8_saturate(lanes.fast_round_int());
        let q = u8x16::narrow_i16x8(q16, q16).to_array();
        Splat {
            depth,
            albedo: [q[1], q[2], q[3]],
            normal: [q[4], q[5], q[6]],
        }
    }
}

impl Pixel for Lanes {
    const EMPTY: Lanes = EMPTY_LANES;

    /// (A mask, not a branch: with a branch the compiler built the vector lane by lane.)
    #[inline(always)]
    fn lanes_within(&self, limit: f32) -> Lanes {
        *self & f32x8::splat(self.depth()).simd_le(f32x8::splat(limit))
    }

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
pub struct DepthMargin {
    pub per_depth: f32,
    pub constant: f32,
}

impl DepthMargin {
    /// The range at `depth`.
    #[inline(always)]
    pub fn at(&self, depth: f32) -> f32 {
        depth.mul_add(self.per_depth, self.constant)
    }
}

/// The nearest of `depths` and the farthest depth still counted as its surface, within
/// `margin` of it; `None` when all are empty ([`EMPTY_DEPTH`]).
#[inline(always)]
fn front(depths: impl Iterator<Item = f32>, margin: DepthMargin) -> Option<(f32, f32)> {
    let nearest = depths.fold(EMPTY_DEPTH, f32::min);
    (nearest < EMPTY_DEPTH).then(|| (nearest, nearest + margin.at(nearest)))
}

/// Averages the front-most group of `candidates` (positive weights, pixels): those
/// within `margin` of the nearest. Empty lanes when all are empty.
#[inline(always)]
pub(crate) fn front_average<P: Pixel>(candidates: &[(f32, P)], margin: DepthMargin) -> Lanes {
    let Some((_, limit)) = front(candidates.iter().map(|(_, p)| p.depth()), margin) else {
        return EMPTY_LANES;
    };
    let sum = candidates.iter().fold(f32x8::ZERO, |sum, (w, p)| {
        p.lanes_within(limit).mul_add(f32x8::splat(*w), sum)
    });
    // The last lane summed the weights.
    sum * f32x8::splat(1.0 / sum.as_array()[7])
}

/// Fills the holes of `layer` using at most `levels` coarser levels; `margin(level)`
/// says what counts as one surface at a level.
pub fn fill(layer: &mut Layer, levels: usize, margin: impl Fn(usize) -> DepthMargin) {
    if layer.width == 0 || layer.height == 0 {
        return;
    }
    // The coarse levels of this thread's last fill are reused: a 1280×720 layer's are
    // 9 MB, and allocating and clearing them anew was a serial pass over all of it
    // (page faults included) before the parallel analysis overwrote every pixel. (So a
    // thread holds on to the largest levels it has filled.)
    let mut pyramid = COARSE_LEVELS.take();
    // Analysis.
    let mut built = 0;
    for level in 0..levels {
        let (w, h) = match built {
            0 => (layer.width, layer.height),
            n => (pyramid[n - 1].width, pyramid[n - 1].height),
        };
        if w <= 1 && h <= 1 {
            break;
        }
        if pyramid.len() == built {
            pyramid.push(Layer::empty(0, 0));
        }
        let (finer, coarser) = pyramid.split_at_mut(built);
        match finer.last() {
            Some(fine) => analyse(fine, margin(level), &mut coarser[0]),
            None => analyse(layer, margin(level), &mut coarser[0]),
        }
        built += 1;
    }
    // Synthesis, coarsest first.
    for level in (0..built).rev() {
        let (upper, lower) = pyramid.split_at_mut(level);
        let (here, above) = (margin(level), margin(level + 1));
        match upper.last_mut() {
            Some(fine) => synthesise(fine, &lower[0], here, above),
            None => synthesise(layer, &lower[0], here, above),
        }
    }
    COARSE_LEVELS.set(pyramid);
}

thread_local! {
    /// The coarse levels [`fill`] last used on this thread (see there).
    static COARSE_LEVELS: std::cell::Cell<Vec<Layer<Lanes>>> = const { std::cell::Cell::new(Vec::new()) };
}

/// A sample position along one axis: two (index, weight) taps. A tap past the border
/// is clamped to the edge pixel (which then counts twice: the same average as leaving
/// it out), so every weight is positive.
type Taps = [(usize, f32); 2];

/// The coarse level: each pixel the front-most average of its 2×2 children (a border
/// pixel's missing ones are the edge's again).
/// Overwrites `coarse` (of any size before) with it.
fn analyse<P: Pixel>(fine: &Layer<P>, margin: DepthMargin, coarse: &mut Layer<Lanes>) {
    let (w, h) = (fine.width.div_ceil(2), fine.height.div_ceil(2));
    let children = |x: usize, fine_len: usize| [2 * x, (2 * x + 1).min(fine_len - 1)];
    let xs: Vec<[usize; 2]> = (0..w).map(|x| children(x, fine.width)).collect();
    // (Every pixel is written below: only new ones need a value here.)
    coarse.pixels.resize(w * h, EMPTY_LANES);
    (coarse.width, coarse.height) = (w, h);
    coarse.pixels.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let [y0, y1] = children(y, fine.height);
        let (r0, r1) = (fine.row(y0), fine.row(y1));
        for (out, &[x0, x1]) in row.iter_mut().zip(&xs) {
            let children = [r0[x0], r0[x1], r1[x0], r1[x1]].map(|c| (1.0, c));
            *out = front_average(&children, margin);
        }
    });
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

/// The fine pixels of one band (one or two rows) and one or two columns share their
/// four coarse candidates (see [`synthesise`]): their nearest depth and which of them
/// count as the front-most surface are found once, for up to four pixels.
struct Shared {
    /// The candidates, the ones behind the front-most group zeroed (so a weighted sum
    /// of all four sums only the front-most group's).
    front: [Lanes; 4],
    /// The candidates' nearest depth (finite: no group is made without one).
    nearest: f32,
    /// Whether all four are in the front-most group: then every pixel's weights sum
    /// to exactly 1 (3/4 and 1/4 both ways, border taps included: dyadic, so the sums
    /// are exact) and its blend needs no division — given that each candidate's last
    /// lane is exactly 1, as the analysis's averages make it (x·(1/x) rounds to 1 for
    /// its sums, 1 to 4 children).
    whole: bool,
}

impl Shared {
    /// The group of `candidates`, or `None` when all are empty (the pixels that share
    /// them stay as they are).
    #[inline(always)]
    fn new(candidates: [Lanes; 4], above: DepthMargin) -> Option<Shared> {
        let (nearest, limit) = front(candidates.iter().map(Pixel::depth), above)?;
        let front = candidates.map(|c| c.lanes_within(limit));
        let whole = candidates.iter().all(|c| c.depth() <= limit);
        Some(Shared {
            front,
            nearest,
            whole,
        })
    }

    /// One fine pixel whose candidates' weights are `weights`: an empty pixel takes the
    /// front-most blend, and a valid pixel well behind it is replaced by it. `here` is
    /// the fine level's surface margin.
    #[inline(always)]
    fn synthesise<P: Pixel>(&self, pixel: &mut P, weights: &[Lanes; 4], here: DepthMargin) {
        let depth = pixel.depth();
        let valid = depth < EMPTY_DEPTH;
        // A valid pixel in front of every candidate stays as it is: skip the blend.
        if valid && depth <= self.nearest + here.at(self.nearest.min(depth)) {
            return;
        }
        let sum = self
            .front
            .iter()
            .zip(weights)
            .fold(f32x8::ZERO, |sum, (c, w)| c.mul_add(*w, sum));
        // The last lane summed the weights (the nearest candidate's at least: positive).
        let blend = match self.whole {
            true => {
                debug_assert_eq!(sum.as_array()[7], 1.0);
                sum
            }
            false => sum * f32x8::splat(1.0 / sum.as_array()[7]),
        };
        let blend_depth = blend.as_array()[0];
        // (Huge depths can overflow the sum, to infinity.)
        if blend_depth < EMPTY_DEPTH && (!valid || depth > blend_depth + here.at(blend_depth)) {
            *pixel = P::from_lanes(blend);
        }
    }
}

/// Fills a level from the one above it. A fine pixel reads the 2×2 coarse pixels
/// around its centre ([`upsampling_taps`]); fine rows (and columns) `2j + 1` and
/// `2j + 2` read the same two coarse ones, so the fine level is walked in bands of two
/// rows (row 0 alone) and pairs of columns (column 0 alone), and each 2×2 block of fine
/// pixels shares one [`Shared`] group of candidates. `here` is the fine level's
/// surface margin, `above` the coarse level's.
fn synthesise<P: Pixel>(fine: &mut Layer<P>, coarse: &Layer<Lanes>, here: DepthMargin, above: DepthMargin) {
    let xs = upsampling_taps(fine.width, coarse.width);
    let ys = upsampling_taps(fine.height, coarse.height);
    let width = fine.width;
    let coarse_rows = |y: usize| {
        let [(y0, _), (y1, _)] = ys[y];
        [coarse.row(y0), coarse.row(y1)]
    };
    let weights = |y: usize| ys[y].map(|(_, w)| w);
    // What the bands and pairs rely on: rows (columns) 2j + 1 and 2j + 2 read the same
    // coarse ones, and every pair has the first pair's weights.
    let shared = |taps: &[Taps], y: usize| taps[y].map(|(i, _)| i) == taps[y + 1].map(|(i, _)| i);
    debug_assert!((1..ys.len().saturating_sub(1)).step_by(2).all(|y| shared(&ys, y)));
    debug_assert!((1..xs.len().saturating_sub(1)).step_by(2).all(|x| shared(&xs, x)));
    debug_assert!((3..xs.len()).all(|x| xs[x][0].1 == xs[1 + (x - 1) % 2][0].1));
    let (first, rest) = fine.pixels.split_at_mut(width);
    synthesise_band([(first, weights(0))], coarse_rows(0), &xs, here, above);
    rest.par_chunks_mut(2 * width).enumerate().for_each(|(j, rows)| {
        let y = 1 + 2 * j;
        match rows.split_at_mut_checked(width) {
            Some((upper, lower)) if !lower.is_empty() => synthesise_band(
                [(upper, weights(y)), (lower, weights(y + 1))],
                coarse_rows(y),
                &xs,
                here,
                above,
            ),
            _ => synthesise_band([(rows, weights(y))], coarse_rows(y), &xs, here, above),
        }
    });
}

/// One band of [`synthesise`]: its `N` fine rows (1 or 2), each with its two coarse
/// rows' weights, and those two coarse rows.
#[inline(always)]
fn synthesise_band<P: Pixel, const N: usize>(
    mut rows: [(&mut [P], [f32; 2]); N],
    coarse: [&[Lanes]; 2],
    xs: &[Taps],
    here: DepthMargin,
    above: DepthMargin,
) {
    let width = xs.len();
    // The four candidates' weights of each pixel of a block starting at column `x`,
    // as vectors. Every pair of columns has the same weights (3/4 and 1/4 one way,
    // then the other; only the indices clamp at the border): the pairs' are made once.
    let row_weights: [[f32; 2]; N] = std::array::from_fn(|r| rows[r].1);
    let weights = |x: usize| -> [[[f32x8; 4]; 2]; N] {
        std::array::from_fn(|r| {
            let [wy0, wy1] = row_weights[r];
            std::array::from_fn(|c| {
                let [(_, wx0), (_, wx1)] = xs[(x + c).min(width - 1)];
                [wy0 * wx0, wy0 * wx1, wy1 * wx0, wy1 * wx1].map(f32x8::splat)
            })
        })
    };
    let first = weights(0);
    synthesise_block::<P, N, 1>(&mut rows, 0, &first, coarse, xs, here, above);
    let mut x = 1;
    if x + 2 <= width {
        let pairs = weights(1);
        while x + 2 <= width {
            synthesise_block::<P, N, 2>(&mut rows, x, &pairs, coarse, xs, here, above);
            x += 2;
        }
    }
    if x < width {
        let last = weights(x);
        synthesise_block::<P, N, 1>(&mut rows, x, &last, coarse, xs, here, above);
    }
}

/// The `N × C` fine pixels of `rows` from column `x` on, which share their candidates,
/// with the candidates' `weights` for each. (Fixed counts: the common 2 × 2 block is
/// straight-line code.)
#[inline(always)]
fn synthesise_block<P: Pixel, const N: usize, const C: usize>(
    rows: &mut [(&mut [P], [f32; 2]); N],
    x: usize,
    weights: &[[[f32x8; 4]; 2]; N],
    [r0, r1]: [&[Lanes]; 2],
    xs: &[Taps],
    here: DepthMargin,
    above: DepthMargin,
) {
    let [(x0, _), (x1, _)] = xs[x];
    debug_assert!(xs[x..x + C].iter().all(|t| t[0].0 == x0 && t[1].0 == x1));
    let Some(shared) = Shared::new([r0[x0], r0[x1], r1[x0], r1[x1]], above) else {
        return;
    };
    for ((row, _), weights) in rows.iter_mut().zip(weights) {
        for c in 0..C {
            shared.synthesise(&mut row[x + c], &weights[c], here);
        }
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
        fill(&mut layer, 1, |_| DepthMargin {
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
        fill(&mut layer, 2, |_| DepthMargin {
            per_depth: 0.0,
            constant: 0.5,
        });
        let p = layer.pixels[3 * 8 + 3];
        assert!((p.depth - 1.0).abs() < 1e-5 && p.albedo == [51; 3], "{p:?}");
    }

    /// A pixel of the plain fill: depth, albedo, normal, and the weight summed into it
    /// (a sample's is 1), in plain `f32`s.
    type Plain = [f32; 8];

    const PLAIN_EMPTY: Plain = [EMPTY_DEPTH, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

    /// The fill written from its definition, sharing no code with it — every coarse
    /// pixel the weighted mean of its 2×2 children (clamped at the border) in front of
    /// the nearest by the level's margin, every fine pixel, if empty or behind the
    /// surface its 2×2 coarse candidates show, replaced by their mean (weights 3/4 and
    /// 1/4 each way, the nearer parent the heavier) — which the fill's shared-candidate
    /// blocks must match within rounding (its sums run in another order) at every
    /// border.
    fn plain_fill(layer: &Layer, levels: usize, margin: impl Fn(usize) -> DepthMargin) -> Vec<Plain> {
        let range = |m: DepthMargin, depth: f32| depth * m.per_depth + m.constant;
        let mean = |candidates: &[(f32, Plain)], m: DepthMargin| -> Plain {
            let nearest = candidates.iter().map(|c| c.1[0]).fold(EMPTY_DEPTH, f32::min);
            if nearest >= EMPTY_DEPTH {
                return PLAIN_EMPTY;
            }
            let limit = nearest + range(m, nearest);
            let mut sum = [0.0f32; 8];
            for (w, p) in candidates.iter().filter(|c| c.1[0] <= limit) {
                for lane in 0..8 {
                    sum[lane] += w * p[lane];
                }
            }
            sum.map(|v| v / sum[7])
        };
        let mut levels_made: Vec<(usize, usize, Vec<Plain>)> = vec![(
            layer.width,
            layer.height,
            (layer.pixels.iter())
                .map(|p| match p.is_valid() {
                    true => {
                        let ([r, g, b], [x, y, z]) = (p.albedo, p.normal);
                        let f = |c: u8| f32::from(c);
                        [p.depth, f(r), f(g), f(b), f(x), f(y), f(z), 1.0]
                    }
                    false => PLAIN_EMPTY,
                })
                .collect(),
        )];
        for level in 0..levels {
            let (w, h, fine) = levels_made.last().expect("the finest");
            let (w, h) = (*w, *h);
            if w <= 1 && h <= 1 {
                break;
            }
            let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
            let mut coarse = vec![PLAIN_EMPTY; cw * ch];
            for y in 0..ch {
                for x in 0..cw {
                    let child = |dx: usize, dy: usize| {
                        (1.0, fine[(2 * y + dy).min(h - 1) * w + (2 * x + dx).min(w - 1)])
                    };
                    coarse[y * cw + x] = mean(
                        &[child(0, 0), child(1, 0), child(0, 1), child(1, 1)],
                        margin(level),
                    );
                }
            }
            levels_made.push((cw, ch, coarse));
        }
        // Fine pixel `x` lies a quarter of a coarse pixel from the nearer parent.
        let parents = |x: usize, coarse: usize| -> [(usize, f32); 2] {
            let (half, last) = (x / 2, coarse - 1);
            if x.is_multiple_of(2) {
                [(half.saturating_sub(1).min(last), 0.25), (half.min(last), 0.75)]
            } else {
                [(half.min(last), 0.75), ((half + 1).min(last), 0.25)]
            }
        };
        for level in (0..levels_made.len() - 1).rev() {
            let (here, above) = (margin(level), margin(level + 1));
            let (cw, ch, coarse) = levels_made[level + 1].clone();
            let (w, h, fine) = &mut levels_made[level];
            for y in 0..*h {
                for x in 0..*w {
                    let mut candidates = Vec::new();
                    for (cy, wy) in parents(y, ch) {
                        for (cx, wx) in parents(x, cw) {
                            candidates.push((wy * wx, coarse[cy * cw + cx]));
                        }
                    }
                    let pixel = &mut fine[y * *w + x];
                    let (depth, valid) = (pixel[0], pixel[0] < EMPTY_DEPTH);
                    let nearest = candidates.iter().map(|c| c.1[0]).fold(EMPTY_DEPTH, f32::min);
                    if valid && depth <= nearest + range(here, nearest.min(depth)) {
                        continue;
                    }
                    let blend = mean(&candidates, above);
                    if blend[0] < EMPTY_DEPTH && (!valid || depth > blend[0] + range(here, blend[0])) {
                        *pixel = blend;
                    }
                }
            }
        }
        levels_made.swap_remove(0).2
    }

    #[test]
    fn matches_the_plain_fill_at_every_size_and_border() {
        // Sparse samples on two surfaces (depth ~1 and ~5), odd and even sizes; the
        // fills of one thread reuse its coarse levels from size to size.
        let mut seed = 0x2545_f491u32;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        let margin = |l: usize| DepthMargin {
            per_depth: 0.02 * (1 << l) as f32,
            constant: 0.01,
        };
        for (width, height) in [(1, 1), (1, 6), (7, 1), (2, 2), (7, 6), (8, 9), (33, 17), (64, 40)] {
            for levels in 1..=4 {
                let mut layer = Layer::new(width, height);
                for pixel in &mut layer.pixels {
                    let r = next();
                    if r % 10 < 4 {
                        let depth = if r % 3 == 0 { 5.0 } else { 1.0 } + (r >> 8) as f32 * 1e-9;
                        *pixel = Splat {
                            depth,
                            albedo: [(r >> 3) as u8, (r >> 11) as u8, (r >> 19) as u8],
                            normal: [(r >> 5) as u8, (r >> 13) as u8, (r >> 21) as u8],
                        };
                    }
                }
                let plain = plain_fill(&layer, levels, margin);
                fill(&mut layer, levels, margin);
                for (k, (got, want)) in layer.pixels.iter().zip(&plain).enumerate() {
                    let at =
                        format!("{width}x{height}, {levels} levels, pixel {k}: {got:?} against {want:?}");
                    assert_eq!(got.is_valid(), want[0] < EMPTY_DEPTH, "{at}");
                    if !got.is_valid() {
                        continue;
                    }
                    assert!((got.depth - want[0]).abs() <= 1e-5 * want[0], "{at}");
                    // (Bytes rounded from means summed in another order: within one.)
                    let bytes = got.albedo.iter().chain(&got.normal).zip(&want[1..7]);
                    assert!(
                        bytes
                            .into_iter()
                            .all(|(&b, &w)| (b as f32 - w.clamp(0.0, 255.0)).abs() <= 1.0),
                        "{at}"
                    );
                }
            }
        }
    }
}
