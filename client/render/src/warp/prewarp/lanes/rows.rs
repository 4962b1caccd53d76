//! A row's samples eight texels at a time, and its spans eight at a time.

use wide::bytemuck::cast;
use wide::{f32x8, u32x8};

use super::vectors::{eight, field, gather, lane_bits, lane_mask, lerp_attributes, load, permute};
use super::{DOWN_LINK, EXACT, LANES, RIGHT_LINK, VALID, first};
use crate::warp::prewarp::texel::{ENTRY_MASK, ENTRY_SHIFT, NORMAL_SHIFT, links_of};
use crate::warp::prewarp::{Cell, Facing, Tables};

/// One half-row's texels in visiting order, as the row pass reads them: where each
/// lands and what it carries, laid out by field so eight load as one vector. (Kept
/// from row to row: only the first `n` of a half-row of `n` texels are its own.)
#[derive(Default)]
pub(in crate::warp::prewarp) struct RowSamples {
    /// u′, v′ and displacement (zero for a texel that is not [`VALID`]).
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub depth: Vec<f32>,
    /// The packed texel ([`pack_texel`](crate::warp::prewarp::pack_texel)): its attributes.
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
        Cell::sample(
            self.v[k],
            self.depth[k],
            self.attributes[k],
            self.flags[k] & DOWN_LINK != 0,
        )
    }

    /// Bit `l` set where the `l`-th of the eight flags from `k` has `flag`.
    #[inline(always)]
    fn mask(&self, k: usize, flag: u8) -> u32 {
        lane_bits(&self.flags[k..k + LANES], flag)
    }
}

/// The row pass's samples of texels `lowest..lowest + 8` of a row (`packed`, its
/// centre at `v`), written to `samples` from `step` in visiting order (rightwards when
/// `RIGHT`): what the scalar pass's loop writes for them, by the same operations in
/// the same order, eight at once.
#[inline(always)]
pub(in crate::warp::prewarp) fn sample_eight<const RIGHT: bool>(
    packed: &[u64],
    lowest: usize,
    v: f32,
    tables: &Tables,
    facing: Option<&Facing>,
    samples: &mut RowSamples,
    step: usize,
) {
    let texels = eight(packed, lowest);
    let entries = field(&texels, ENTRY_SHIFT, ENTRY_MASK.count_ones());
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
            f32x8::from_i32x8(cast(field(&texels, NORMAL_SHIFT + byte, 8))) - f32x8::splat(127.5)
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
            permute(x, u32x8::from([7, 6, 5, 4, 3, 2, 1, 0])).to_array()
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
        *flags = ((valid >> l) & 1) as u8 * VALID + links_of(*texel);
    }
    samples.attributes[at].copy_from_slice(&texels);
}

/// The samples a [`row_block`] made: one for each of `count` consecutive pre-warped
/// columns from `first` (lane `l` for column `first + l`, whichever way the row
/// pass went: each went to a column of its own, so their order does not matter).
#[derive(Default)]
pub(in crate::warp::prewarp) struct Emitted {
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
        Cell::sample(
            self.v[l],
            self.depth[l],
            self.attributes[l],
            self.down & (1 << l) != 0,
        )
    }
}

/// The spans ending at texels `k..k + 8` of `samples` (the run's last sample is
/// `k − 1`; its last span has a length, so its first sample's share is drawn), visited
/// rightwards when `RIGHT`: the leading ones that continue the run with at most two
/// pixel centres each (eight in all) and away from an epipole far off, taken as eight
/// lanes — the pixels each holds and its sample interpolated there, as
/// [`between`](crate::warp::prewarp::between) and a linear interpolation make them, into `emitted`.
/// Returns how many texels it took: 0 when it cannot take the first.
///
/// (Two centres: a view turned from the texture's eye stretches the surfaces it turns
/// towards. Turned 40°, 5,454 of the 5,870 blocks of the knot's 256² texture that
/// stopped short stopped at a span of two, when one was the most.)
#[inline(always)]
pub(in crate::warp::prewarp) fn row_block<const RIGHT: bool>(
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
    let two = f32x8::splat(2.0);
    let at_most_two = centres.simd_le(two);
    let valid = samples.mask(k, VALID);
    // Rightwards the left texel carries the link; leftwards the one visited.
    let linked = samples.mask(if RIGHT { k - 1 } else { k }, RIGHT_LINK);
    let taken_lanes = valid & linked & (exact & ahead & at_most_two).to_bitmask();
    let mut taken = (!taken_lanes).trailing_zeros().min(LANES as u32);
    // A block's samples fit one column block: eight.
    let (some, pairs) = (
        centres.simd_ge(f32x8::ONE).to_bitmask(),
        centres.simd_eq(two).to_bitmask(),
    );
    if pairs & first(taken) != 0 {
        while (some & first(taken)).count_ones() + (pairs & first(taken)).count_ones() > LANES as u32 {
            taken -= 1;
        }
    }
    let ends = f32x8::splat(end as f32);
    // The first centre past `a`, and where there are two, the second (`below_b`).
    let first_centre = below_a + f32x8::ONE;
    let emits = some & first_centre.simd_le(ends).to_bitmask() & first(taken);
    let seconds = pairs & below_b.simd_le(ends).to_bitmask() & first(taken);
    let count = (emits.count_ones() + seconds.count_ones()) as usize;
    (emitted.count, emitted.down) = (count, 0);
    if emits != 0 {
        let inv = f32x8::ONE / (b - a);
        let at = |centre: f32x8| ((centre + half - a) * inv).fast_clamp(f32x8::ZERO, f32x8::ONE);
        let t = at(first_centre);
        let (va, vb) = (load(&samples.v, k - 1), load(&samples.v, k));
        let (da, db) = (load(&samples.depth, k - 1), load(&samples.depth, k));
        let (attributes_a, attributes_b) = (eight(&samples.attributes, k - 1), eight(&samples.attributes, k));
        let v = va + (vb - va) * t;
        let depth = da + (db - da) * t;
        let attributes = lerp_attributes(&attributes_a, &attributes_b, t);
        let down = samples.mask(k - 1, DOWN_LINK) & samples.mask(k, DOWN_LINK);
        // The visit's first column, and the image's: leftwards, signed `x` is `−x − 1`.
        let visit_first = first_centre.to_array()[emits.trailing_zeros() as usize] as i64;
        emitted.first = if RIGHT {
            visit_first
        } else {
            -visit_first - count as i64
        };
        if seconds == 0 {
            // Column `c` (from the image's first) takes lane `order[c]`.
            let order = compaction::<RIGHT>(emits, count);
            (emitted.v, emitted.depth) = (permute(v, order).to_array(), permute(depth, order).to_array());
            for (column, &l) in emitted.attributes.iter_mut().zip(&order.to_array()) {
                *column = attributes[l as usize & (LANES - 1)];
            }
            emitted.down = lane_mask(down).shuffle(order).to_bitmask() & first(count as u32);
        } else {
            let t = at(below_b);
            let second = (
                (va + (vb - va) * t).to_array(),
                (da + (db - da) * t).to_array(),
                lerp_attributes(&attributes_a, &attributes_b, t),
            );
            #[cfg(test)]
            super::tests::PAIRS_TAKEN.with(|n| n[0].set(n[0].get() + seconds.count_ones() as usize));
            let first_ones = (v.to_array(), depth.to_array(), attributes);
            // In the visit's order, each lane's first sample, then its second.
            let mut j = 0;
            for l in 0..taken as usize {
                for (which, samples) in [(emits, &first_ones), (seconds, &second)] {
                    if which & (1 << l) != 0 {
                        let column = if RIGHT { j } else { count - 1 - j };
                        emitted.v[column] = samples.0[l];
                        emitted.depth[column] = samples.1[l];
                        emitted.attributes[column] = samples.2[l];
                        emitted.down |= ((down >> l) & 1) << column;
                        j += 1;
                    }
                }
            }
        }
    }
    #[cfg(test)]
    super::tests::TAKEN_IN_ROWS
        .with(|n| n[usize::from(RIGHT)].set(n[usize::from(RIGHT)].get() + taken as usize));
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

#[cfg(test)]
mod tests {
    /// The permutation puts each emitted lane in the column the per-lane loop it
    /// replaced put it in (the `j`-th emitted lane in column `j` rightwards, `count − 1
    /// − j` leftwards), for every set of lanes; and their links downwards along.
    #[test]
    fn compaction_orders_emitted_lanes_into_columns() {
        use super::super::first;
        use super::super::vectors::lane_mask;
        use super::compaction;
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
}
