//! The interleaved pre-warp eight texels at a time, where the surface is smooth.
//!
//! Seen a few degrees from its eye, a texture's texels land about one pre-warped pixel
//! apart: most spans between connected neighbours hold one pixel centre, or none, and
//! the column each lands in continues a run there. Eight such spans are computed as one
//! vector ([`row_block`]): where each lands, whether it holds a centre, the
//! interpolated sample there. Their samples fall in consecutive columns, and those eight
//! columns take their next sample as one vector too ([`Columns::take_block`]). Lanes
//! that meet anything else — a run's end, a crack, a span of two centres or more, a
//! column starting a run — go through the scalar code: a row's in the visit's order, a
//! column's after the block's vector step (each lane is a column of its own, so no
//! write of one comes between another's).
//!
//! # Same pixels
//!
//! Every lane computes exactly what the scalar pass computes, with the same operations
//! in the same order (Rust never fuses a multiply and an add on its own), so the image
//! is bit for bit the one the scalar pass makes: the tests compare the two.

use wide::f32x8;

use super::{Attributes, Cell, Column, Output};
use crate::warp::round_small;

/// Lanes per block.
pub(super) const LANES: usize = 8;

/// Coordinates up to this size convert exactly between `f32` and integers, with room
/// for the half-pixel offsets; beyond it (an epipole far off) the scalar code runs.
const EXACT: f32 = 4_000_000.0;

/// [`RowSamples::flags`]: the texel holds a surface that shows from the eye.
pub(super) const VALID: u8 = 1;
/// The texel is connected to its right neighbour.
pub(super) const RIGHT_LINK: u8 = 2;
/// The texel is connected to the one below.
pub(super) const DOWN_LINK: u8 = 4;

/// One half-row's texels in visiting order, as the row pass reads them: where each
/// lands and what it carries, laid out by field so eight load as one vector.
#[derive(Default)]
pub(super) struct RowSamples {
    /// u′, v′ and displacement (zero for a texel that is not [`VALID`]).
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub depth: Vec<f32>,
    /// The packed texel ([`pack_texel`](super::pack_texel)): its attributes.
    pub attributes: Vec<u64>,
    /// [`VALID`], [`RIGHT_LINK`], [`DOWN_LINK`].
    pub flags: Vec<u8>,
}

impl RowSamples {
    /// The arrays sized for `n` texels (their memory kept from row to row), to be
    /// written whole.
    pub fn resize(&mut self, n: usize) {
        for field in [&mut self.u, &mut self.v, &mut self.depth] {
            field.resize(n, 0.0);
        }
        self.attributes.resize(n, 0);
        self.flags.resize(n, 0);
    }

    /// The sample at `k`, as the scalar pass takes it.
    #[inline(always)]
    pub fn cell(&self, k: usize) -> Cell {
        Cell {
            v: self.v[k],
            depth: self.depth[k],
            attributes: Attributes(self.attributes[k]),
            down: self.flags[k] & DOWN_LINK != 0,
            filler: false,
        }
    }

    /// Bit `l` set where the `l`-th of the eight flags from `k` has `flag`.
    #[inline(always)]
    fn mask(&self, k: usize, flag: u8) -> u32 {
        lane_bits(&self.flags[k..k + LANES], flag)
    }
}

/// Bit `l` of the result is whether `bytes[l]` has `flag`: the eight bytes as one word,
/// each reduced to its flag's bit, gathered into the top byte by one multiply (each
/// product term lands on a bit of its own, so nothing carries).
#[inline(always)]
fn lane_bits(bytes: &[u8], flag: u8) -> u32 {
    let Some(bytes) = bytes.first_chunk::<8>() else {
        return 0;
    };
    let word = u64::from_le_bytes(*bytes);
    let ones = (word >> flag.trailing_zeros()) & 0x0101_0101_0101_0101;
    (ones.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32
}

#[inline(always)]
fn load(values: &[f32], at: usize) -> f32x8 {
    match values[at..].first_chunk::<8>() {
        Some(lanes) => f32x8::from(*lanes),
        None => f32x8::ZERO,
    }
}

/// Lanes `0..n` set.
#[inline(always)]
pub(super) fn first(n: u32) -> u32 {
    (1u32 << n) - 1
}

/// The samples a [`row_block`] made: one for each of `count` consecutive pre-warped
/// columns from `first` (lane `l` for column `first + l`, whichever way the row
/// pass went: each went to a column of its own, so their order does not matter).
#[derive(Default)]
pub(super) struct Emitted {
    pub count: usize,
    pub first: i64,
    pub v: [f32; LANES],
    pub depth: [f32; LANES],
    pub attributes: [u64; LANES],
    /// Bit `l`: lane `l`'s link downwards.
    pub down: u32,
}

impl Emitted {
    /// Lane `l`'s sample.
    #[inline(always)]
    pub fn cell(&self, l: usize) -> Cell {
        Cell {
            v: self.v[l],
            depth: self.depth[l],
            attributes: Attributes(self.attributes[l]),
            down: self.down & (1 << l) != 0,
            filler: false,
        }
    }
}

/// The spans ending at texels `k..k + 8` of `samples` (the run's last sample is
/// `k − 1`; its last span has a length, so its first sample's share is drawn), visited
/// rightwards when `RIGHT`: the leading ones that continue the run with at most one
/// pixel centre each and away from an epipole far off, taken as eight lanes — the
/// pixel each holds and its sample interpolated there, as
/// [`between`](super::between) and a linear interpolation make them, into `emitted`.
/// Returns how many texels it took: 0 when it cannot take the first.
#[inline(always)]
pub(super) fn row_block<const RIGHT: bool>(
    samples: &RowSamples,
    k: usize,
    end: i64,
    emitted: &mut Emitted,
) -> usize {
    let sign = f32x8::splat(if RIGHT { 1.0 } else { -1.0 });
    let (a, b) = (load(&samples.u, k - 1) * sign, load(&samples.u, k) * sign);
    let half = f32x8::splat(0.5);
    let (below_a, below_b) = ((a - half).floor(), (b - half).floor());
    let centres = below_b - below_a;
    let exact = a.abs().simd_lt(f32x8::splat(EXACT)) & b.abs().simd_lt(f32x8::splat(EXACT));
    let ahead = b.simd_ge(a);
    let at_most_one = centres.simd_le(f32x8::ONE);
    let valid = samples.mask(k, VALID);
    // Rightwards the left texel carries the link; leftwards the one visited.
    let linked = samples.mask(if RIGHT { k - 1 } else { k }, RIGHT_LINK);
    let taken_lanes = valid & linked & (exact & ahead & at_most_one).to_bitmask();
    let taken = (!taken_lanes).trailing_zeros().min(LANES as u32);
    let ends = f32x8::splat(end as f32);
    let one = centres.simd_eq(f32x8::ONE) & below_b.simd_le(ends);
    let emits = one.to_bitmask() & first(taken);
    let count = emits.count_ones() as usize;
    (emitted.count, emitted.down) = (count, 0);
    if emits != 0 {
        let t = ((below_b + half - a) * (f32x8::ONE / (b - a))).fast_clamp(f32x8::ZERO, f32x8::ONE);
        let (va, vb) = (load(&samples.v, k - 1), load(&samples.v, k));
        let (da, db) = (load(&samples.depth, k - 1), load(&samples.depth, k));
        let v = (va + (vb - va) * t).to_array();
        let depth = (da + (db - da) * t).to_array();
        let (t, below_b) = (t.to_array(), below_b.to_array());
        let down = samples.mask(k - 1, DOWN_LINK) & samples.mask(k, DOWN_LINK);
        // The visit's first column, and the image's: leftwards, signed `x` is `−x − 1`.
        let visit_first = below_b[emits.trailing_zeros() as usize] as i64;
        emitted.first = if RIGHT {
            visit_first
        } else {
            -visit_first - count as i64
        };
        let mut lanes = emits;
        for j in 0..count {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let column = if RIGHT { j } else { count - 1 - j };
            emitted.v[column] = v[l];
            emitted.depth[column] = depth[l];
            emitted.attributes[column] = Attributes(samples.attributes[k - 1 + l])
                .lerp(
                    Attributes(samples.attributes[k + l]),
                    round_small(t[l] * 256.0).min(256) as u64,
                )
                .0;
            emitted.down |= ((down >> l) & 1) << column;
        }
    }
    #[cfg(test)]
    tests::TAKEN_IN_ROWS.with(|n| n[usize::from(RIGHT)].set(n[usize::from(RIGHT)].get() + taken as usize));
    taken as usize
}

/// Every pre-warped column's state in the column pass ([`Column`]), with a block's
/// width to spare at the end, so that eight columns from any one can be read at once.
/// (Field by field, the scalar column step read six arrays where it reads one column
/// here, and ran 1.6× slower.)
pub(super) struct Columns {
    len: usize,
    columns: Vec<Column>,
}

impl Columns {
    pub fn new(len: usize) -> Columns {
        Columns {
            len,
            columns: vec![Column::START; len + LANES],
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    #[inline(always)]
    pub fn get(&self, i: usize) -> Column {
        self.columns[i]
    }

    #[inline(always)]
    pub fn set(&mut self, i: usize, column: Column) {
        self.columns[i] = column;
    }

    /// Feeds `emitted`, made by row number `seq`, into its columns (image columns from
    /// `base`), visited downwards when `DOWN_ROWS`: each lane that continues its
    /// column's run with at most one pixel centre, as eight lanes; and returns the
    /// others (bit `l` for lane `l`) for the scalar column step.
    #[inline(always)]
    pub fn take_block<const DOWN_ROWS: bool>(
        &mut self,
        emitted: &Emitted,
        base: usize,
        seq: u32,
        out: &mut Output,
    ) -> u32 {
        let n = emitted.count;
        let cell_down = emitted.down;
        let (mut adjacent, mut last_down, mut filler) = (0u32, 0u32, 0u32);
        let Some(block) = self.columns[base..].first_chunk::<LANES>() else {
            return first(n as u32);
        };
        let (mut last_v, mut last_depth, mut last_gap) = ([0f32; LANES], [0f32; LANES], [0f32; LANES]);
        for (l, column) in block.iter().enumerate() {
            (last_v[l], last_depth[l], last_gap[l]) = (column.last.v, column.last.depth, column.last_gap);
            adjacent |= u32::from(seq != 0 && column.next_row == seq) << l;
            last_down |= u32::from(column.last.down) << l;
            filler |= u32::from(column.last.filler) << l;
        }
        // Downwards the previous row's sample carries the link; upwards this one.
        let linked = adjacent & if DOWN_ROWS { last_down } else { cell_down & !filler };
        let sign = f32x8::splat(if DOWN_ROWS { 1.0 } else { -1.0 });
        let (last_v, cell_v) = (f32x8::from(last_v), f32x8::from(emitted.v));
        let (a, b) = (last_v * sign, cell_v * sign);
        let half = f32x8::splat(0.5);
        let (below_a, below_b) = ((a - half).floor(), (b - half).floor());
        let centres = below_b - below_a;
        let exact = a.abs().simd_lt(f32x8::splat(EXACT)) & b.abs().simd_lt(f32x8::splat(EXACT));
        let gap_known = !f32x8::from(last_gap).is_nan();
        let simple = exact & b.simd_ge(a) & centres.simd_le(f32x8::ONE) & gap_known;
        let taken = linked & simple.to_bitmask() & first(n as u32);
        #[cfg(test)]
        tests::TAKEN_IN_COLUMNS.with(|c| {
            let c = &c[usize::from(DOWN_ROWS)];
            c.set(c.get() + taken.count_ones() as usize)
        });
        let end = super::signed_end::<DOWN_ROWS>(out.v0..out.v1);
        let puts =
            taken & (centres.simd_eq(f32x8::ONE) & below_b.simd_le(f32x8::splat(end as f32))).to_bitmask();
        if puts != 0 {
            let t = ((below_b + half - a) * (f32x8::ONE / (b - a))).fast_clamp(f32x8::ZERO, f32x8::ONE);
            let last_depth = f32x8::from(last_depth);
            let depth = (last_depth + (f32x8::from(emitted.depth) - last_depth) * t).to_array();
            let (t, below_b) = (t.to_array(), below_b.to_array());
            let mut lanes = puts;
            while lanes != 0 {
                let l = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let attributes = block[l].last.attributes.lerp(
                    Attributes(emitted.attributes[l]),
                    round_small(t[l] * 256.0).min(256) as u64,
                );
                let y = below_b[l] as i64;
                out.put_texel(
                    base + l,
                    if DOWN_ROWS { y } else { -y - 1 },
                    attributes.texel(depth[l]),
                );
            }
        }
        let gaps = (cell_v - last_v).to_array();
        let mut lanes = taken;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            self.set(
                base + l,
                Column {
                    last: emitted.cell(l),
                    next_row: seq + 1,
                    last_gap: gaps[l],
                },
            );
        }
        first(n as u32) & !taken
    }
}

#[cfg(test)]
pub(super) mod tests {
    use std::cell::Cell;

    use glam::{Quat, Vec3};
    use relief_core::relief::{DepthBits, SourceProjection};
    use relief_core::scene::Scene;
    use relief_trace::{bake, tracer::ObjectTracer};

    use super::super::{PlaneWindow, PrewarpImage, Variant, prewarp_with};
    use crate::impostor::{Faces, Impostor};
    use crate::warp::params::WarpParams;

    thread_local! {
        /// Texels the row blocks took on this thread, visiting leftwards and rightwards.
        pub(in super::super) static TAKEN_IN_ROWS: [Cell<usize>; 2] = const { [Cell::new(0), Cell::new(0)] };
        /// Samples the column blocks took, visiting upwards and downwards.
        pub(in super::super) static TAKEN_IN_COLUMNS: [Cell<usize>; 2] = const { [Cell::new(0), Cell::new(0)] };
    }

    /// The image's placement, and each texel's depth bits and attribute bytes.
    fn bits(image: &PrewarpImage) -> Vec<u64> {
        let texels = image.texels.iter().flat_map(|t| {
            let [r, g, b] = t.attributes.albedo();
            let [x, y, z] = t.attributes.normal();
            [
                t.depth.to_bits().into(),
                u64::from_le_bytes([r, g, b, x, y, z, 0, 0]),
            ]
        });
        let placement = [
            image.u0 as u64,
            image.v0 as u64,
            image.width.into(),
            image.height.into(),
        ];
        placement.into_iter().chain(texels).collect()
    }

    /// Eight lanes at a time make the very image the scalar pass makes, bit for bit:
    /// a self-occluding knot and a tree of leaves (cracks, runs of one texel), baked
    /// orthographic and perspective, 8- and 16-bit, all faces or the front ones, seen
    /// from eyes turned every way, nearer and farther than the texture's (so visited
    /// towards the epipole and outwards), whole and through a window. A good share of
    /// the texels go through the lanes (fails if they stop being used).
    #[test]
    fn eight_lanes_make_the_scalar_image() {
        let scene = Scene::load("default").expect("default scene");
        let (mut cases, mut visited) = (0, 0);
        let counts = || {
            let read = |cells: &[Cell<usize>; 2]| [cells[0].get(), cells[1].get()];
            (TAKEN_IN_ROWS.with(read), TAKEN_IN_COLUMNS.with(read))
        };
        let (rows_before, columns_before) = counts();
        for name in ["knot", "tree"] {
            let object = scene.object(name).expect("object");
            let tracer = ObjectTracer::new(object);
            let centre = object.local_bounds.center();
            let radius = object.local_bounds.extent().length() * 0.5;
            let eye = centre + Vec3::new(0.0, 0.25, 1.0).normalize() * 3.0 * radius;
            for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
                for depth_bits in [DepthBits::Eight, DepthBits::Sixteen] {
                    let texture = bake(&tracer, eye, 96, depth_bits, projection).expect("baked");
                    for faces in [Faces::Both, Faces::Front] {
                        let impostor = Impostor::new(texture.clone()).with_faces(faces);
                        for (yaw, pitch) in [(-40.0f32, 0.0f32), (-5.0, 3.0), (4.0, -20.0), (25.0, 12.0)] {
                            for distance in [0.6, 1.0, 2.0] {
                                let turn = Quat::from_rotation_y(yaw.to_radians())
                                    * Quat::from_rotation_x(pitch.to_radians());
                                let moved = centre + turn * (eye - centre) * distance;
                                let Ok(params) = WarpParams::new(&impostor.texture, moved) else {
                                    continue;
                                };
                                let window = PlaneWindow {
                                    u0: 30.0,
                                    v0: -4.0,
                                    u1: 70.0,
                                    v1: 60.0,
                                };
                                for seen in [None, Some(&window)] {
                                    let warp = |lanes| {
                                        prewarp_with(
                                            &impostor,
                                            &params,
                                            Variant::Interleaved,
                                            seen,
                                            false,
                                            lanes,
                                        )
                                    };
                                    let lanes = warp(true);
                                    assert!(
                                        bits(&lanes) == bits(&warp(false)),
                                        "{name} {projection:?} {depth_bits:?} {faces:?} yaw {yaw} pitch {pitch} \
                                         ×{distance} window {}",
                                        seen.is_some()
                                    );
                                    cases += 1;
                                    visited += lanes.visited;
                                }
                            }
                        }
                    }
                }
            }
        }
        let (rows, columns) = counts();
        let took = |after: [usize; 2], before: [usize; 2]| [after[0] - before[0], after[1] - before[1]];
        let (rows, columns) = (took(rows, rows_before), took(columns, columns_before));
        assert!(cases >= 150, "{cases} cases");
        // Each way of visiting rows and columns takes its share in lanes (of every texel
        // visited, empty ones included, when written: rows 15 and 17 %, columns 10 %
        // each way).
        for (what, taken) in [("rows", rows), ("columns", columns)] {
            for (way, n) in ["backwards", "forwards"].iter().zip(taken) {
                assert!(
                    n * 20 > visited,
                    "{what} visited {way}: {n} of {visited} texels in lanes"
                );
            }
        }
    }
}
