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

use wide::bytemuck::cast;
use wide::{f32x8, i16x8, u8x16, u16x16, u32x8, u64x4};

use super::{Attributes, Cell, Column, Facing, Output, PTexel, Tables};

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
/// lands and what it carries, laid out by field so eight load as one vector. (Kept
/// from row to row: only the first `n` of a half-row of `n` texels are its own.)
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
    /// The arrays made at least `n` texels long (their memory kept from row to row),
    /// the first `n` to be written whole. (Only growing: resized to each half-row, they
    /// cost 4 % of the pre-warp's instructions.)
    #[inline(always)]
    pub fn resize(&mut self, n: usize) {
        if self.flags.len() >= n {
            return;
        }
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

/// `values[index[l]]` for each lane; an index past the end reads the last value, or
/// zero from an empty table.
#[inline(always)]
fn gather(values: &[f32], index: u32x8) -> f32x8 {
    let Some(last) = values.len().checked_sub(1) else {
        return f32x8::ZERO;
    };
    let index = index.min(u32x8::splat(last as u32));
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{__m256i, _mm256_i32gather_ps};
        let index: __m256i = cast(index);
        // SAFETY: every lane reads `values[index]`, each index clamped within `values`
        // (not empty); the gather only reads.
        cast(unsafe { _mm256_i32gather_ps::<4>(values.as_ptr(), index) })
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    f32x8::from(index.to_array().map(|i| values[i as usize]))
}

/// Bits `shift..shift + width` of each of eight words, one per lane.
#[inline(always)]
fn field(words: &[u64; LANES], shift: u32, width: u32) -> u32x8 {
    let [low, high] = cast::<[u64; LANES], [u64x4; 2]>(*words);
    let mask = u64x4::splat((1 << width) - 1);
    // `low`'s in the even 32-bit lanes, `high`'s in the odd; then in order.
    let paired = cast::<u64x4, u32x8>(((low >> shift) & mask) | (((high >> shift) & mask) << 32));
    paired.shuffle(u32x8::from([0, 2, 4, 6, 1, 3, 5, 7]))
}

/// The row pass's samples of texels `lowest..lowest + 8` of a row (`packed`, its
/// centre at `v`), written to `samples` from `step` in visiting order (rightwards when
/// `RIGHT`): what the scalar pass's loop writes for them, by the same operations in
/// the same order, eight at once.
#[inline(always)]
pub(super) fn sample_eight<const RIGHT: bool>(
    packed: &[u64],
    lowest: usize,
    v: f32,
    tables: &Tables,
    facing: Option<&Facing>,
    samples: &mut RowSamples,
    step: usize,
) {
    let texels = eight(packed, lowest);
    let entries = field(&texels, super::ENTRY_SHIFT, super::ENTRY_MASK.count_ones());
    let surface = entries.simd_lt(u32x8::splat(tables.scale.len() as u32));
    let (scale, add_u, add_v, depth) = (
        gather(tables.scale, entries),
        gather(tables.add_u, entries),
        gather(tables.add_v, entries),
        gather(tables.depth, entries),
    );
    // Each texel's centre along the row (whole numbers and halves: exact).
    let u = f32x8::splat(lowest as f32)
        + f32x8::from([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
        + f32x8::splat(0.5);
    let mut valid = surface.to_bitmask();
    if let Some(f) = facing {
        let towards = |eye: f32, a: f32, ray: f32, ray_step: f32| {
            f32x8::splat(eye) - f32x8::splat(a) * u - (f32x8::splat(ray) + f32x8::splat(ray_step) * u) * depth
        };
        let (e, a, r, s) = (f.row_eye, f.a, f.ray, f.ray_step);
        let to_eye = [
            towards(e.x, a.x, r.x, s.x),
            towards(e.y, a.y, r.y, s.y),
            towards(e.z, a.z, r.z, s.z),
        ];
        let normal = [0, 8, 16].map(|byte| {
            f32x8::from_i32x8(cast(field(&texels, super::NORMAL_SHIFT + byte, 8))) - f32x8::splat(127.5)
        });
        let dot = normal[0] * to_eye[0] + normal[1] * to_eye[1] + normal[2] * to_eye[2];
        valid &= !dot.simd_lt(f32x8::ZERO).to_bitmask();
    }
    let kept = cast::<u32x8, f32x8>(lane_mask(valid));
    let or_zero = |x: f32x8| kept.select(x, f32x8::ZERO);
    let lands = [
        or_zero((u + add_u) * scale),
        or_zero((f32x8::splat(v) + add_v) * scale),
        or_zero(depth),
    ];
    let in_visit = |x: f32x8| {
        if RIGHT {
            x.to_array()
        } else {
            cast::<u32x8, f32x8>(cast::<f32x8, u32x8>(x).shuffle(u32x8::from([7, 6, 5, 4, 3, 2, 1, 0])))
                .to_array()
        }
    };
    let at = step..step + LANES;
    for (field, lands) in [&mut samples.u, &mut samples.v, &mut samples.depth]
        .into_iter()
        .zip(lands)
    {
        field[at.clone()].copy_from_slice(&in_visit(lands));
    }
    let mut texels = texels;
    if !RIGHT {
        texels.reverse();
        valid = valid.reverse_bits() >> (32 - LANES);
    }
    for (l, (flags, texel)) in samples.flags[at.clone()].iter_mut().zip(&texels).enumerate() {
        *flags = ((valid >> l) & 1) as u8 * VALID + super::links_of(*texel);
    }
    samples.attributes[at].copy_from_slice(&texels);
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

/// The eight values from `at`, or zeros past the end.
#[inline(always)]
fn eight<T: Copy + Default>(values: &[T], at: usize) -> [T; LANES] {
    values
        .get(at..)
        .and_then(|rest| rest.first_chunk::<LANES>())
        .copied()
        .unwrap_or_default()
}

#[inline(always)]
fn load(values: &[f32], at: usize) -> f32x8 {
    f32x8::from(eight(values, at))
}

#[inline(always)]
fn load_u32(values: &[u32], at: usize) -> u32x8 {
    u32x8::from(eight(values, at))
}

/// All ones in the four 64-bit lanes whose bit is set in `bits`'s low four.
#[inline(always)]
fn wide_mask(bits: u32) -> u64x4 {
    let each = u64x4::from([1, 2, 4, 8]);
    (u64x4::splat(u64::from(bits)) & each).simd_eq(each)
}

/// All ones in the lanes whose bit is set in `bits`.
#[inline(always)]
fn lane_mask(bits: u32) -> u32x8 {
    let each = u32x8::from([1, 2, 4, 8, 16, 32, 64, 128]);
    (u32x8::splat(bits) & each).simd_eq(each)
}

/// [`Attributes::lerp`] of eight pairs at once, `a[l]` towards `b[l]` by `t[l] ∈ [0,
/// 1]` (each weight rounded as there): two texels' bytes to a vector of sixteen
/// 16-bit lanes, the same arithmetic, the same bytes.
#[inline(always)]
fn lerp_attributes(a: &[u64; LANES], b: &[u64; LANES], t: f32x8) -> [u64; LANES] {
    // (`round_small(t·256).min(256)`, eight at once: the sum's low mantissa bits are
    // the rounded integer; NaN's bits give 256, as there.)
    let rounded = cast::<f32x8, u32x8>(t * f32x8::splat(256.0) + f32x8::splat(8_388_608.0));
    let weight = (rounded & u32x8::splat(0x7f_ffff)).min(u32x8::splat(256));
    // Each weight in both 16-bit halves of its lane.
    let weight = weight | (weight << 16u32);
    let mut mixed = [0u64; LANES];
    for pair in 0..LANES / 2 {
        let (l, m) = (2 * pair as u32, 2 * pair as u32 + 1);
        let t = cast::<u32x8, u16x16>(weight.shuffle(u32x8::from([l, l, l, l, m, m, m, m])));
        let bytes = |x: &[u64; LANES]| u16x16::from(cast::<[u64; 2], u8x16>([x[2 * pair], x[2 * pair + 1]]));
        let blended = (bytes(a) * (u16x16::splat(256) - t) + bytes(b) * t + u16x16::splat(128)) >> 8;
        let [low, high] = cast::<u16x16, [i16x8; 2]>(blended);
        let [first, second] = cast::<u8x16, [u64; 2]>(u8x16::narrow_i16x8(low, high));
        (mixed[2 * pair], mixed[2 * pair + 1]) = (first, second);
    }
    mixed
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
        let v = va + (vb - va) * t;
        let depth = da + (db - da) * t;
        let attributes = lerp_attributes(
            &eight(&samples.attributes, k - 1),
            &eight(&samples.attributes, k),
            t,
        );
        let down = samples.mask(k - 1, DOWN_LINK) & samples.mask(k, DOWN_LINK);
        // The visit's first column, and the image's: leftwards, signed `x` is `−x − 1`.
        let visit_first = below_b.to_array()[emits.trailing_zeros() as usize] as i64;
        emitted.first = if RIGHT {
            visit_first
        } else {
            -visit_first - count as i64
        };
        // Column `c` (from the image's first) takes lane `order[c]`.
        let order = compaction::<RIGHT>(emits, count);
        let by_column = |x: f32x8| cast::<u32x8, f32x8>(cast::<f32x8, u32x8>(x).shuffle(order));
        (emitted.v, emitted.depth) = (by_column(v).to_array(), by_column(depth).to_array());
        for (column, &l) in emitted.attributes.iter_mut().zip(&order.to_array()) {
            *column = attributes[l as usize & (LANES - 1)];
        }
        emitted.down = lane_mask(down).shuffle(order).to_bitmask() & first(count as u32);
    }
    #[cfg(test)]
    tests::TAKEN_IN_ROWS.with(|n| n[usize::from(RIGHT)].set(n[usize::from(RIGHT)].get() + taken as usize));
    taken as usize
}

/// For each set of lanes (bit `l` for lane `l`), the set lanes in order, then
/// zeros: where each of a block's emitted samples comes from.
const IN_ORDER: [[u8; LANES]; 1 << LANES] = {
    let mut table = [[0; LANES]; 1 << LANES];
    let mut set = 0;
    while set < 1 << LANES {
        let (mut l, mut n) = (0, 0);
        while l < LANES {
            if set & (1 << l) != 0 {
                table[set][n] = l as u8;
                n += 1;
            }
            l += 1;
        }
        set += 1;
    }
    table
};

/// The lane each of the `count` pre-warped columns of a block takes, among the lanes
/// `emits`: in order rightwards; leftwards, the last emitted lane is the first column.
#[inline(always)]
fn compaction<const RIGHT: bool>(emits: u32, count: usize) -> u32x8 {
    let order = u32x8::from(IN_ORDER[emits as usize & 0xff].map(u32::from));
    if RIGHT {
        order
    } else {
        let reversed =
            (u32x8::splat(count as u32 - 1) - u32x8::from([0, 1, 2, 3, 4, 5, 6, 7])) & u32x8::splat(7);
        order.shuffle(reversed)
    }
}

/// Every pre-warped column's state in the column pass ([`Column`]), field by field so
/// that eight columns from any one load as vectors, with a block's width to spare at
/// the end.
pub(super) struct Columns {
    len: usize,
    v: Vec<f32>,
    depth: Vec<f32>,
    attributes: Vec<u64>,
    /// [`LAST_DOWN`], [`LAST_FILLER`].
    links: Vec<u32>,
    next_row: Vec<u32>,
    last_gap: Vec<f32>,
}

/// [`Columns::links`]: the column's last sample links downwards ([`Cell::down`]).
const LAST_DOWN: u32 = 1;
/// The column's last sample filled a crack ([`Cell::filler`]).
const LAST_FILLER: u32 = 2;

impl Columns {
    pub fn new(len: usize) -> Columns {
        let n = len + LANES;
        let start = Column::START;
        Columns {
            len,
            v: vec![start.last.v; n],
            depth: vec![start.last.depth; n],
            attributes: vec![start.last.attributes.0; n],
            links: vec![0; n],
            next_row: vec![start.next_row; n],
            last_gap: vec![start.last_gap; n],
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    #[inline(always)]
    pub fn get(&self, i: usize) -> Column {
        let links = self.links[i];
        Column {
            last: Cell {
                v: self.v[i],
                depth: self.depth[i],
                attributes: Attributes(self.attributes[i]),
                down: links & LAST_DOWN != 0,
                filler: links & LAST_FILLER != 0,
            },
            next_row: self.next_row[i],
            last_gap: self.last_gap[i],
        }
    }

    #[inline(always)]
    pub fn set(&mut self, i: usize, column: Column) {
        let last = column.last;
        self.v[i] = last.v;
        self.depth[i] = last.depth;
        self.attributes[i] = last.attributes.0;
        self.links[i] = u32::from(last.down) * LAST_DOWN + u32::from(last.filler) * LAST_FILLER;
        self.next_row[i] = column.next_row;
        self.last_gap[i] = column.last_gap;
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
        if base + LANES > self.v.len() {
            return first(n as u32);
        }
        let (last_v, last_depth) = (load(&self.v, base), load(&self.depth, base));
        let links = load_u32(&self.links, base);
        let adjacent = if seq == 0 {
            0
        } else {
            load_u32(&self.next_row, base)
                .simd_eq(u32x8::splat(seq))
                .to_bitmask()
        };
        let has = |flag: u32| {
            let flag = u32x8::splat(flag);
            (links & flag).simd_eq(flag).to_bitmask()
        };
        // Downwards the previous row's sample carries the link; upwards this one.
        let linked = adjacent
            & if DOWN_ROWS {
                has(LAST_DOWN)
            } else {
                emitted.down & !has(LAST_FILLER)
            };
        let sign = f32x8::splat(if DOWN_ROWS { 1.0 } else { -1.0 });
        let cell_v = f32x8::from(emitted.v);
        let (a, b) = (last_v * sign, cell_v * sign);
        let half = f32x8::splat(0.5);
        let (below_a, below_b) = ((a - half).floor(), (b - half).floor());
        let centres = below_b - below_a;
        let exact = a.abs().simd_lt(f32x8::splat(EXACT)) & b.abs().simd_lt(f32x8::splat(EXACT));
        let gap_known = !load(&self.last_gap, base).is_nan();
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
        let last_attributes = eight(&self.attributes, base);
        if puts != 0 {
            let t = ((below_b + half - a) * (f32x8::ONE / (b - a))).fast_clamp(f32x8::ZERO, f32x8::ONE);
            let depth = (last_depth + (f32x8::from(emitted.depth) - last_depth) * t).to_array();
            let attributes = lerp_attributes(&last_attributes, &emitted.attributes, t);
            // (Whole numbers below `EXACT`: they convert exactly, as vectors; one by one
            // to `i64`, each saturating conversion cost a tenth of the column step.)
            let rows = below_b.fast_trunc_int().to_array();
            let mut lanes = puts;
            while lanes != 0 {
                let l = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let y = i64::from(rows[l]);
                out.put_texel(
                    base + l,
                    if DOWN_ROWS { y } else { -y - 1 },
                    PTexel {
                        depth: depth[l],
                        attributes: Attributes(attributes[l]),
                    },
                );
            }
        }
        if taken == 0 {
            return first(n as u32);
        }
        // The taken lanes' samples become their columns' last.
        let mask = lane_mask(taken);
        let keep = |new: f32x8, old: f32x8| cast::<u32x8, f32x8>(mask).select(new, old).to_array();
        let at = base..base + LANES;
        self.v[at.clone()].copy_from_slice(&keep(cell_v, last_v));
        let depth = keep(f32x8::from(emitted.depth), last_depth);
        self.depth[at.clone()].copy_from_slice(&depth);
        let gap = keep(cell_v - last_v, load(&self.last_gap, base));
        self.last_gap[at.clone()].copy_from_slice(&gap);
        let cell_links = lane_mask(emitted.down) & u32x8::splat(LAST_DOWN);
        self.links[at.clone()].copy_from_slice(&mask.select(cell_links, links).to_array());
        let next = mask.select(u32x8::splat(seq + 1), load_u32(&self.next_row, base));
        self.next_row[at].copy_from_slice(&next.to_array());
        let [low, high] = cast::<[u64; LANES], [u64x4; 2]>(emitted.attributes);
        let [old_low, old_high] = cast::<[u64; LANES], [u64x4; 2]>(last_attributes);
        let kept = [
            wide_mask(taken).select(low, old_low),
            wide_mask(taken >> 4).select(high, old_high),
        ];
        self.attributes[base..base + LANES].copy_from_slice(&cast::<[u64x4; 2], [u64; LANES]>(kept));
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

    /// Eight lanes at a time make the very image the scalar pass makes, bit for bit,
    /// and so does visiting each row whole rather than its occupied texels only:
    /// a self-occluding knot and a tree of leaves (cracks, runs of one texel), baked
    /// orthographic and perspective, 8- and 16-bit, all faces or the front ones, seen
    /// from eyes turned every way, nearer and farther than the texture's (so visited
    /// towards the epipole and outwards), whole and through a window. A good share of
    /// the texels go through the lanes (fails if they stop being used).
    #[test]
    fn eight_lanes_make_the_scalar_image() {
        let scene = Scene::load("default").expect("default scene");
        let (mut cases, mut visited, mut whole_visited) = (0, 0, 0);
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
                        // The same, visiting every texel of each row.
                        let whole_rows = Impostor {
                            occupied: vec![0..texture.camera.width as usize; texture.camera.height as usize],
                            ..impostor.clone()
                        };
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
                                    let warp = |impostor: &Impostor, lanes| {
                                        prewarp_with(
                                            impostor,
                                            &params,
                                            Variant::Interleaved,
                                            seen,
                                            false,
                                            lanes,
                                        )
                                    };
                                    let lanes = warp(&impostor, true);
                                    let scalar = bits(&warp(&impostor, false));
                                    let whole = warp(&whole_rows, false);
                                    whole_visited += whole.visited;
                                    assert!(
                                        scalar == bits(&whole),
                                        "occupied texels only: {name} {projection:?} {depth_bits:?} {faces:?} \
                                         yaw {yaw} pitch {pitch} ×{distance} window {}",
                                        seen.is_some()
                                    );
                                    assert!(
                                        bits(&lanes) == scalar,
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
        // The rows' occupied texels leave out a good share of the whole rows (when
        // written: 1.43 M of 2.73 M texels visited).
        assert!(
            visited * 4 < whole_visited * 3,
            "{visited} texels visited, {whole_visited} in whole rows"
        );
        // Each way of visiting rows and columns takes its share in lanes (of every texel
        // visited, empty ones within rows included, when written: rows 27 and 30 %,
        // columns 18 and 19 %).
        for (what, taken) in [("rows", rows), ("columns", columns)] {
            for (way, n) in ["backwards", "forwards"].iter().zip(taken) {
                assert!(
                    n * 10 > visited,
                    "{what} visited {way}: {n} of {visited} texels in lanes"
                );
            }
        }
    }

    /// The permutation puts each emitted lane in the column the per-lane loop it
    /// replaced put it in (the `j`-th emitted lane in column `j` rightwards, `count − 1
    /// − j` leftwards), for every set of lanes; and their links downwards along.
    #[test]
    fn compaction_orders_emitted_lanes_into_columns() {
        use super::{compaction, first, lane_mask};
        for emits in 1u32..256 {
            let count = emits.count_ones() as usize;
            let lanes: Vec<u32> = (0..8).filter(|l| emits & (1 << l) != 0).collect();
            for right in [true, false] {
                let order = if right {
                    compaction::<true>(emits, count)
                } else {
                    compaction::<false>(emits, count)
                };
                let order = order.to_array();
                for (j, &l) in lanes.iter().enumerate() {
                    let column = if right { j } else { count - 1 - j };
                    assert_eq!(order[column], l, "lanes {emits:08b} rightwards {right}");
                }
                // Down links: a lane's bit goes to its column.
                for down in [0u32, 0b1010_0101, 0xff, emits] {
                    let moved =
                        lane_mask(down).shuffle(wide::u32x8::from(order)).to_bitmask() & first(count as u32);
                    let expected = lanes.iter().enumerate().fold(0, |m, (j, &l)| {
                        let column = if right { j } else { count - 1 - j };
                        m | (((down >> l) & 1) << column)
                    });
                    assert_eq!(
                        moved, expected,
                        "lanes {emits:08b} down {down:08b} rightwards {right}"
                    );
                }
            }
        }
    }

    /// Eight blends at once give each pair the bytes [`Attributes::lerp`] gives it,
    /// with the same rounded weight: at the ends, at ties between weights, at NaN, and
    /// at random bytes and weights.
    #[test]
    fn eight_attribute_blends_equal_one_at_a_time() {
        use super::super::Attributes;
        use super::lerp_attributes;
        use crate::warp::round_small;
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let special = [
            0.0,
            1.0,
            0.5 / 256.0,
            1.5 / 256.0,
            127.5 / 256.0,
            255.5 / 256.0,
            f32::NAN,
            1e-9,
        ];
        for round in 0..200 {
            let a: [u64; 8] = std::array::from_fn(|_| next());
            let b: [u64; 8] = std::array::from_fn(|_| next());
            let t: [f32; 8] = if round == 0 {
                special
            } else {
                std::array::from_fn(|_| (next() % 100_001) as f32 / 100_000.0)
            };
            let blended = lerp_attributes(&a, &b, wide::f32x8::from(t));
            for l in 0..8 {
                let weight = round_small(t[l] * 256.0).min(256) as u64;
                let one = Attributes(a[l]).lerp(Attributes(b[l]), weight);
                assert_eq!(
                    (Attributes(blended[l]).albedo(), Attributes(blended[l]).normal()),
                    (one.albedo(), one.normal()),
                    "t {}",
                    t[l]
                );
            }
        }
    }
}
