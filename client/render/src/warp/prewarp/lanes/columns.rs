//! The column pass's state, field by field, and its steps eight columns at a time.

use wide::bytemuck::cast;
use wide::{f32x8, u32x8, u64x4};

use super::vectors::{eight, lane_mask, lerp_attributes, load, load_u32, wide_mask};
use super::{EXACT, Emitted, LANES, first};
use crate::warp::prewarp::{Attributes, Cell, Column, Output, PTexel, signed_end};
use relief_core::shading::set_lanes;

/// Every pre-warped column's state in the column pass ([`Column`]), field by field so
/// that eight columns from any one load as vectors, with a block's width to spare at
/// the end.
pub(in crate::warp::prewarp) struct Columns {
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
    /// column's run with at most two pixel centres, as eight lanes; and returns the
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
        let two = f32x8::splat(2.0);
        let simple = exact & b.simd_ge(a) & centres.simd_le(two) & gap_known;
        let taken = linked & simple.to_bitmask() & first(n as u32);
        #[cfg(test)]
        super::tests::TAKEN_IN_COLUMNS.with(|c| {
            let c = &c[usize::from(DOWN_ROWS)];
            c.set(c.get() + taken.count_ones() as usize)
        });
        let ends = f32x8::splat(signed_end::<DOWN_ROWS>(out.v0..out.v1) as f32);
        // The first centre past `a`, and where there are two, the second (`below_b`).
        let first_centre = below_a + f32x8::ONE;
        let puts = taken & (centres.simd_ge(f32x8::ONE) & first_centre.simd_le(ends)).to_bitmask();
        let last_attributes = eight(&self.attributes, base);
        if puts != 0 {
            let inv = f32x8::ONE / (b - a);
            let next = f32x8::from(emitted.depth);
            let mut put = |centre: f32x8, lanes: u32| {
                let t = ((centre + half - a) * inv).fast_clamp(f32x8::ZERO, f32x8::ONE);
                let depth = (last_depth + (next - last_depth) * t).to_array();
                let attributes = lerp_attributes(&last_attributes, &emitted.attributes, t);
                // (Whole numbers below `EXACT`: they convert exactly, as vectors; one by
                // one to `i64`, each saturating conversion cost a tenth of the column step.)
                let rows = centre.fast_trunc_int().to_array();
                for l in set_lanes(lanes) {
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
            };
            put(first_centre, puts);
            let seconds = puts & (centres.simd_eq(two) & below_b.simd_le(ends)).to_bitmask();
            if seconds != 0 {
                #[cfg(test)]
                super::tests::PAIRS_TAKEN.with(|n| n[1].set(n[1].get() + seconds.count_ones() as usize));
                put(below_b, seconds);
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
