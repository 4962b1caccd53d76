//! The pre-warp (ch. 3.4, 8.2): every texel moved within the source plane to where the
//! destination eye sees it, holes between neighbours filled by interpolation, texels
//! visited in occlusion-compatible order so that later writes win.
//!
//! Order: the epipole splits rows and columns into halves; each half is visited from the
//! border towards the epipole. (Each texel moves towards the epipole by `s ∈ (0, 1]`, the
//! deeper the more, so of two texels landing on one spot the one nearer the epipole in
//! the source is the nearer surface — it must come last.) A perspective texture seen
//! from farther than its centre moves texels away from the epipole, the deeper the more
//! ([`WarpParams::outward`]): the nearer surface is then the one farther from the
//! epipole, and each half is visited from the epipole outwards. Either way texels stay
//! on their side of the epipole, and consecutive texels of a surface move apart ahead of
//! the visit.
//!
//! Filling: consecutive texels A, B of a row (connected — one surface, see
//! [`Impostor`] — and moving in the visiting direction) produce every pre-warped pixel
//! whose centre lies in `(A', B']`, interpolated. A run of connected texels reaches half
//! its first span behind its first sample and half its last span past its last (at most
//! half a pixel each): each sample owns the half-way points to its neighbours, so a
//! silhouette lies where the surface's samples put it. (Giving a run's end sample the
//! whole pixel it lands in grows a silhouette by half a pixel on average where the
//! pre-warp compresses the surface, at a curved object's rim.) A texel alone produces
//! the pixel it lands in. Neighbours of different surfaces that part leave a crack
//! between them, which the deeper of the two fills (`Job::crack`) — but for the half
//! beside the nearer where its surface, closed, rounds out of sight there
//! (`Job::crack_fillers`). The column pass does the same with consecutive samples of a
//! column. The variants differ in what reaches the column pass (table 8.1):
//!
//! - [`Variant::OneD`]: the row pass stores interpolated depth; the column pass computes
//!   each sample's v' from it — interpolating what was already interpolated.
//! - [`Variant::Asymmetric`]: the row pass also stores each sample's final v'.
//! - [`Variant::Compensated`]: as `OneD`, but an interpolated sample takes the depth of
//!   the point on the 3D segment A–B that pre-warps exactly to its pixel (the purpose of
//!   eq. 8-1, solved here in closed form for orthographic textures) instead of a linear
//!   blend; a perspective texture's samples blend linearly.
//! - [`Variant::Interleaved`]: one pass; each row sample goes straight into its column.
//!   Where a surface is smooth it takes eight texels at a time (module `lanes`), to the bit
//!   the same image.
//!
//! # Layout
//!
//! This module holds the passes (`Job`) and their entry points; beside it:
//! - `texel`: a pre-warped texel ([`PTexel`]) and the packed attribute bytes the
//!   passes blend;
//! - `image`: the pre-warped image ([`PrewarpImage`]), how far it reaches, and the
//!   rectangle of the source plane the screen sees ([`PlaneWindow`]) with the texels
//!   that can land in it;
//! - `spans`: the order of the visit (each half of an axis from the border towards
//!   the epipole, or outwards), the pixels between two samples visited either way, and
//!   a run's reach past its ends;
//! - `cracks`: what fills the cracks between surfaces that part;
//! - `lanes`: the row and column passes eight texels at a time.

mod cracks;
mod image;
mod lanes;
mod spans;
mod texel;

use glam::Vec3;

use self::cracks::fill_column_crack;
pub use self::image::{PlaneWindow, PrewarpImage};
use self::image::{WINDOW_MARGIN, extent, reaching};
#[cfg(test)]
pub(crate) use self::lanes::tests::baked_from;
use self::lanes::{Columns, Emitted, LANES, RIGHT_LINK, RowSamples, VALID, first, row_block};
pub(crate) use self::lanes::{field, lerp_attributes};
use self::spans::{between, reach_ahead, reach_behind, signed_end, split_at, visited};
pub use self::texel::PTexel;
pub(crate) use self::texel::{Attributes, NORMAL_SHIFT, pack_texel};
use self::texel::{entry_of, links_of};
use super::params::WarpParams;
use crate::impostor::{Faces, Impostor};

/// Pre-warp sampling variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    OneD,
    Asymmetric,
    Compensated,
    Interleaved,
}

impl Variant {
    /// Every variant, in table 8.1's order.
    pub const ALL: [Variant; 4] = [
        Variant::OneD,
        Variant::Asymmetric,
        Variant::Compensated,
        Variant::Interleaved,
    ];
}

/// A texel in the row pass: its source u, where it lands along the row (u'), and what
/// goes on to the column pass.
#[derive(Debug, Clone, Copy)]
struct RowSample {
    source: f32,
    u: f32,
    cell: Cell,
}

/// What the column pass reads of a sample: its v' (final, or where its row is before
/// the column pass), displacement, attributes and link downwards; and whether the row
/// pass made it to fill a crack ([`Job::crack`]), linked to no other row.
#[derive(Debug, Clone, Copy)]
struct Cell {
    v: f32,
    depth: f32,
    attributes: Attributes,
    down: bool,
    filler: bool,
}

impl Cell {
    const START: Cell = Cell {
        v: 0.0,
        depth: 0.0,
        attributes: Attributes(0),
        down: false,
        filler: false,
    };

    /// A sample the row pass made from a texel (never a crack's filler): where it lands
    /// in its row, `v`, its displacement, its attribute bytes and its link downwards.
    #[inline(always)]
    fn sample(v: f32, depth: f32, attributes: u64, down: bool) -> Cell {
        Cell {
            v,
            depth,
            attributes: Attributes(attributes),
            down,
            filler: false,
        }
    }

    /// Of two samples of different surfaces, the one farther from the texture's eye.
    #[inline(always)]
    fn deeper(self, other: Cell) -> Cell {
        let far = if other.depth > self.depth { other } else { self };
        Cell {
            down: false,
            filler: true,
            ..far
        }
    }

    #[inline(always)]
    fn lerp(&self, other: &Cell, t: f32) -> Cell {
        Cell {
            v: self.v + (other.v - self.v) * t,
            depth: self.depth + (other.depth - self.depth) * t,
            // (`min`: a NaN `t`, from NaN input, must not underflow the lanes.)
            attributes: self
                .attributes
                .lerp(other.attributes, super::round_small(t * 256.0).min(256) as u64),
            down: self.down && other.down,
            filler: false,
        }
    }
}

/// Per-column state of the column pass: the column's last sample, and one past the
/// number (in visiting order) of the row that produced it — 0 before any; and, as in
/// the row pass, the run of connected samples it ends: the run's last span, NaN while
/// it has none (its first sample still owes its half-span behind it). Its end is drawn
/// when a sample does not continue it. (Kept field by field in [`Columns`], so that
/// eight columns load as vectors.)
#[derive(Clone, Copy)]
struct Column {
    last: Cell,
    next_row: u32,
    last_gap: f32,
}

impl Column {
    const START: Column = Column {
        last: Cell::START,
        next_row: 0,
        last_gap: f32::NAN,
    };

    /// Draws the end of the column's run, if it has one ([`reach_ahead`]).
    #[inline(always)]
    fn close<const DOWN: bool>(&self, column_index: usize, out: &mut Output) {
        if self.next_row == 0 {
            return;
        }
        let end = signed_end::<DOWN>(out.v0..out.v1);
        let last = self.last;
        reach_ahead::<DOWN>(last.v, self.last_gap, end, |y| out.put(column_index, y, &last));
    }
}

/// The rows of the pre-warped image one half of the work writes: all its columns (the
/// pass's, from the image's first), and plane rows from `v0`.
struct Output<'a> {
    texels: &'a mut [PTexel],
    /// The plane rows `v0..v1` held.
    v0: i64,
    v1: i64,
    width: usize,
}

impl Output<'_> {
    /// Writes `cell` at column `xi` of the image (counted from its first, so already
    /// within it: a column of the pass) and plane row `y`, if that row is held.
    #[inline(always)]
    fn put(&mut self, xi: usize, y: i64, cell: &Cell) {
        self.put_texel(xi, y, cell.attributes.texel(cell.depth));
    }

    /// Writes `texel` as [`Output::put`] writes a cell.
    #[inline(always)]
    fn put_texel(&mut self, xi: usize, y: i64, texel: PTexel) {
        let yy = y - self.v0;
        if yy < 0 {
            return;
        }
        if let Some(t) = self.texels.get_mut(yy as usize * self.width + xi) {
            *t = texel;
        }
    }
}

/// Where the row pass's pixels go.
trait RowSink {
    /// The row pass made `cell` for pre-warped column `x`.
    fn emit(&mut self, x: i64, cell: Cell);

    /// The row pass made `emitted`, for consecutive columns (see
    /// [`lanes::row_block`]).
    #[inline(always)]
    fn emit_block(&mut self, emitted: &Emitted) {
        for l in 0..emitted.count {
            self.emit(emitted.first + l as i64, emitted.cell(l));
        }
    }
}

/// [`Variant::Interleaved`]: each row sample straight into its column, row number
/// `seq` of a half visited downwards when `DOWN`.
struct IntoColumns<'a, 'b, 'o, const DOWN: bool> {
    job: &'a Job<'a>,
    columns: &'b mut Columns,
    out: &'b mut Output<'o>,
    seq: u32,
}

impl<const DOWN: bool> RowSink for IntoColumns<'_, '_, '_, DOWN> {
    #[inline(always)]
    fn emit(&mut self, x: i64, cell: Cell) {
        self.job
            .push_column::<DOWN>(self.columns, self.out, x, cell, self.seq);
    }

    /// Eight columns at once where they continue their runs simply
    /// ([`Columns::take_block`]), the others one by one.
    #[inline(always)]
    fn emit_block(&mut self, emitted: &Emitted) {
        let (n, base) = (emitted.count as i64, emitted.first - self.job.u0);
        let others = if base >= 0 && base + n <= self.columns.len() as i64 {
            self.columns
                .take_block::<DOWN>(emitted, base as usize, self.seq, self.out)
        } else {
            first(n as u32)
        };
        for l in relief_core::shading::set_lanes(others) {
            self.emit(emitted.first + l as i64, emitted.cell(l));
        }
    }
}

/// The two-pass variants: into one row of the intermediate image (a column's last
/// sample wins), whose column `k` is pre-warped column `u0 + k`.
struct IntoRow<'a> {
    row: &'a mut [Option<Cell>],
    u0: i64,
}

impl RowSink for IntoRow<'_> {
    #[inline(always)]
    fn emit(&mut self, x: i64, cell: Cell) {
        let k = x - self.u0;
        if let Some(slot) = (k >= 0).then(|| self.row.get_mut(k as usize)).flatten() {
            *slot = Some(cell);
        }
    }
}

/// Where a row's texels face, to leave out back faces ([`Faces::Front`]): the eye seen
/// from the row's plane origin, how a texel's plane point moves along the row (`a`),
/// and its ray (scaled to 1 along `f`) and how that moves.
#[derive(Clone, Copy)]
struct Facing {
    row_eye: Vec3,
    a: Vec3,
    ray: Vec3,
    ray_step: Vec3,
}

/// The warp's tables ([`WarpParams`]), sliced to the surface entries: an entry past
/// them is the empty texel's, so one comparison tells a surface texel and bounds every
/// read.
#[derive(Clone, Copy)]
struct Tables<'a> {
    scale: &'a [f32],
    add_u: &'a [f32],
    add_v: &'a [f32],
    depth: &'a [f32],
}

impl<'a> Tables<'a> {
    fn of(p: &'a WarpParams) -> Tables<'a> {
        let entries = usize::from(p.levels.empty());
        let tables = [&p.scale, &p.add_u, &p.add_v, &p.depth];
        debug_assert!(
            tables.iter().all(|table| table.len() == entries),
            "pre-warp tables of {entries} entries (not params without tables)"
        );
        let entries = tables.iter().fold(entries, |n, table| n.min(table.len()));
        Tables {
            scale: &p.scale[..entries],
            add_u: &p.add_u[..entries],
            add_v: &p.add_v[..entries],
            depth: &p.depth[..entries],
        }
    }
}

/// What both halves of a pre-warp read.
struct Job<'a> {
    impostor: &'a Impostor,
    params: &'a WarpParams,
    /// `params`' tables, for the row pass.
    tables: Tables<'a>,
    variant: Variant,
    u0: i64,
    columns: usize,
    /// The texels of each row visited: those before the epipole, and those after it —
    /// all, or those that can land where the screen sees (and of these, each row's
    /// occupied ones: [`Job::row_texels`]).
    row_halves: [std::ops::Range<usize>; 2],
    /// Whether the interleaved variant takes texels eight at a time where it can
    /// ([`lanes`]); off only to test that it makes the same image.
    lanes: bool,
    /// The texture's axes, to tell which way a sample's surface runs.
    axes: Axes,
    /// Whether its surfaces are closed ([`Faces::Front`]), going on round past their
    /// outlines ([`Job::crack_fillers`]): a sheet's edge, a leaf's, may be where it ends.
    closed: bool,
}

/// A texture's unit axes: `a` along its rows, `b` down its columns, `f` along its rays
/// (a perspective texture's central one).
#[derive(Debug, Clone, Copy)]
struct Axes {
    a: Vec3,
    b: Vec3,
    f: Vec3,
}

impl Job<'_> {
    /// The row pass over source row `j`: `sink.emit(x, cell)` for each pre-warped
    /// pixel, the texels before the epipole visited rightwards, then the others
    /// leftwards — or, [`WarpParams::outward`], each half from the epipole outwards.
    #[inline(always)]
    fn row(
        &self,
        j: usize,
        interpolate: impl Fn(&RowSample, &RowSample, f32, f32) -> Cell + Copy,
        sink: &mut impl RowSink,
        samples: &mut RowSamples,
    ) {
        let [before, after] = self.row_texels(j);
        if self.params.outward {
            self.row_half::<false>(j, before, interpolate, sink, samples);
            self.row_half::<true>(j, after, interpolate, sink, samples);
        } else {
            self.row_half::<true>(j, before, interpolate, sink, samples);
            self.row_half::<false>(j, after, interpolate, sink, samples);
        }
    }

    /// The texels of source row `j` the row pass visits, before the epipole and after
    /// it: those of [`Job::row_halves`] within the row's occupied texels
    /// ([`Impostor::occupied`]; the empty ones around them make no pixel).
    fn row_texels(&self, j: usize) -> [std::ops::Range<usize>; 2] {
        let width = self.impostor.texture.camera.width as usize;
        let occupied = self.impostor.occupied.get(j).cloned().unwrap_or(0..width);
        self.row_halves.clone().map(|half| {
            let start = half.start.max(occupied.start);
            start..half.end.min(occupied.end).max(start)
        })
    }

    /// The texels `texels` of source row `j` into `samples`, in visiting order
    /// (rightwards when `RIGHT`): where each lands and what it carries; a texel that is
    /// empty, or a back face turned away from the eye, is not [`VALID`]. With
    /// [`Job::lanes`], eight texels at once ([`lanes::sample_eight`]): the same
    /// samples, whatever the variant.
    #[inline(always)]
    fn sample_row<const RIGHT: bool>(
        &self,
        j: usize,
        texels: std::ops::Range<usize>,
        samples: &mut RowSamples,
    ) {
        let (impostor, p) = (self.impostor, self.params);
        let texture = &impostor.texture;
        let w = texture.camera.width as usize;
        let row = j * w..(j + 1) * w;
        let packed = &impostor.packed[row];
        let v = j as f32 + 0.5;
        // With the back faces hidden, the eye seen from this row's texels (before their
        // column and depth): a texel is turned away when its normal points away from it.
        // A texel's surface point is `Q + ray·d`, its plane point `Q` moving by `a` per
        // texel along the row, its ray (scaled to 1 along `f`) by `ray_step`.
        let facing = (impostor.faces == Faces::Front).then(|| {
            let c = &texture.camera;
            let (ray, ray_step) = match (c.centre, c.centre_distance()) {
                (Some(centre), Some(h_s)) => ((c.origin + c.b * v - centre) / h_s, c.a / h_s),
                _ => (c.f, Vec3::ZERO),
            };
            Facing {
                row_eye: p.eye - c.origin - c.b * v,
                a: c.a,
                ray,
                ray_step,
            }
        });
        let turned_away = |i: usize, texel: u64, q: usize| {
            facing.is_some_and(|f| {
                let u = i as f32 + 0.5;
                let to_eye = f.row_eye - f.a * u - (f.ray + f.ray_step * u) * p.depth[q];
                Attributes(texel).normal_direction().dot(to_eye) < 0.0
            })
        };
        let n = texels.len();
        // (The tables' slices in locals: reached through `self` inside the loop, they
        // were loaded again for every texel, the stores below possibly aliasing them.)
        let tables = self.tables;
        samples.resize(n);
        let mut start = 0;
        if self.lanes {
            while start + LANES <= n {
                // The eight texels' lowest index, whichever way the row is visited.
                let lowest = if RIGHT {
                    texels.start + start
                } else {
                    texels.end - start - LANES
                };
                lanes::sample_eight::<RIGHT>(packed, lowest, v, &tables, facing.as_ref(), samples, start);
                start += LANES;
            }
        }
        let Tables {
            scale: scales,
            add_u: add_us,
            add_v: add_vs,
            depth: table_depths,
        } = tables;
        let entries = scales.len();
        let (us, vs, depths) = (&mut samples.u[..n], &mut samples.v[..n], &mut samples.depth[..n]);
        let (attributes, flags) = (&mut samples.attributes[..n], &mut samples.flags[..n]);
        for step in start..n {
            let i = visited::<RIGHT>(&texels, step);
            let texel = packed[i];
            let q = entry_of(texel) as usize;
            let valid = q < entries && !turned_away(i, texel, q);
            let (u, v, depth) = if valid {
                let scale = scales[q];
                (
                    (i as f32 + 0.5 + add_us[q]) * scale,
                    (v + add_vs[q]) * scale,
                    table_depths[q],
                )
            } else {
                (0.0, 0.0, 0.0)
            };
            (us[step], vs[step], depths[step]) = (u, v, depth);
            // (The depth's table entry and the links in the top lanes blend along
            // unread.)
            attributes[step] = texel;
            flags[step] = u8::from(valid) * VALID + links_of(texel);
        }
    }

    /// The texels `texels` of source row `j`, visited rightwards when `RIGHT`:
    /// consecutive connected texels A, B produce every pixel whose centre lies in
    /// `(A', B']`, made by `interpolate(a, b, centre, t)`; a run's end samples reach
    /// half a span beyond it ([`half_gap`](spans::half_gap)); a texel alone (without a connected
    /// neighbour, or folding back behind it) produces the pixel it lands in.
    ///
    /// The interleaved variant takes eight texels at once where the run goes on simply
    /// ([`lanes`]): the same pixels.
    #[inline(always)]
    fn row_half<const RIGHT: bool>(
        &self,
        j: usize,
        texels: std::ops::Range<usize>,
        interpolate: impl Fn(&RowSample, &RowSample, f32, f32) -> Cell,
        sink: &mut impl RowSink,
        samples: &mut RowSamples,
    ) {
        self.sample_row::<RIGHT>(j, texels.clone(), samples);
        let in_lanes = self.lanes && self.variant == Variant::Interleaved;
        let sample = |k: usize| RowSample {
            source: visited::<RIGHT>(&texels, k) as f32 + 0.5,
            u: samples.u[k],
            cell: samples.cell(k),
        };
        // The previous texel visited, and whether it is there and connected to the next.
        let mut previous = RowSample {
            source: 0.0,
            u: 0.0,
            cell: Cell::START,
        };
        let mut previous_linked = false;
        // The run of connected texels being drawn: the length of its last span, NaN
        // while it has none (its first sample still owes the half of its extent behind
        // it; its last sample's half ahead is as long as half of that span).
        let mut last_gap = f32::NAN;
        let end = signed_end::<RIGHT>(self.u0..self.u0 + self.columns as i64);
        // Ends the run whose last sample is `previous` ([`reach_ahead`]).
        let close = |previous: &RowSample, last_gap: f32, sink: &mut _| {
            let cell = previous.cell;
            reach_ahead::<RIGHT>(previous.u, last_gap, end, |x| RowSink::emit(sink, x, cell))
        };
        let mut in_run = false;
        let n = texels.len();
        let mut emitted = Emitted::default();
        let mut k = 0;
        while k < n {
            if in_lanes && in_run && !last_gap.is_nan() && k + LANES <= n {
                let taken = row_block::<RIGHT>(samples, k, end, &mut emitted);
                if taken > 0 {
                    if emitted.count > 0 {
                        sink.emit_block(&emitted);
                    }
                    k += taken;
                    let last = k - 1;
                    last_gap = samples.u[last] - samples.u[last - 1];
                    previous = sample(last);
                    previous_linked = !RIGHT || samples.flags[last] & RIGHT_LINK != 0;
                    if taken == LANES || k == n {
                        continue;
                    }
                }
            }
            let flags = samples.flags[k];
            if flags & VALID == 0 {
                if in_run {
                    close(&previous, last_gap, sink);
                    in_run = false;
                }
                previous_linked = false;
                // (And the empty texels after it: the gaps within a row.)
                k += 1;
                while k < n && samples.flags[k] & VALID == 0 {
                    k += 1;
                }
                continue;
            }
            let sample = sample(k);
            let right = flags & RIGHT_LINK != 0;
            // Visiting rightwards the left texel carries the link; leftwards this one.
            let spanned = previous_linked
                && (RIGHT || right)
                && between::<RIGHT>(previous.u, sample.u, end, |x, t| {
                    sink.emit(x, interpolate(&previous, &sample, x as f32 + 0.5, t))
                });
            if spanned {
                let gap = sample.u - previous.u;
                if last_gap.is_nan() {
                    // The run's first sample: the half-span behind it.
                    let cell = previous.cell;
                    reach_behind::<RIGHT>(previous.u, gap, end, |x| sink.emit(x, cell));
                }
                last_gap = gap;
            } else {
                if in_run {
                    close(&previous, last_gap, sink);
                    // (`in_run`: the previous texel, of another surface or folded
                    // behind this one.)
                    let outline = self.outline(j, &previous, &sample);
                    let (a, b) = ((&previous.cell, previous.u), (&sample.cell, sample.u));
                    self.crack::<RIGHT>(self.axes.a, a, last_gap, b, end, outline, |x, filler| {
                        sink.emit(x, *filler)
                    });
                }
                last_gap = f32::NAN;
            }
            in_run = true;
            previous = sample;
            previous_linked = !RIGHT || right;
            k += 1;
        }
        if in_run {
            close(&previous, last_gap, sink);
        }
    }

    /// Where the outline of the deeper of `a` and `b`, neighbours in source row `j`
    /// parting at a crack, lands along the row, where the texture knows it ends behind
    /// the nearer ([`Impostor::outlines`]).
    #[inline]
    fn outline(&self, j: usize, a: &RowSample, b: &RowSample) -> Option<f32> {
        if self.impostor.outlines.is_empty() {
            return None;
        }
        let (nearer, deeper) = if b.cell.depth > a.cell.depth {
            (a, b)
        } else {
            (b, a)
        };
        let texel = j * self.impostor.texture.camera.width as usize + nearer.source as usize;
        let key = Impostor::outline_key(texel, deeper.source > nearer.source);
        let &(at, depth) = self.impostor.outlines.get(&key)?;
        Some(self.params.warp_at(at, depth).x)
    }

    /// Feeds `cell`, made by row number `seq` (in visiting order, downwards when
    /// `DOWN`) for pre-warped column `x`, into that column: every pixel whose centre
    /// lies between the column's last sample and it when the two are connected rows,
    /// with the runs' ends as in the row pass (a run ends when a sample does not
    /// continue it; [`Job::close_columns`] ends those left at the last row).
    #[inline(always)]
    fn push_column<const DOWN: bool>(
        &self,
        columns: &mut Columns,
        out: &mut Output,
        x: i64,
        cell: Cell,
        seq: u32,
    ) {
        let xi = x - self.u0;
        if xi < 0 || xi >= columns.len() as i64 {
            return;
        }
        // (The image has a column per pass column: this one is within it.)
        let column_index = xi as usize;
        let column = &columns.get(column_index);
        // Visiting downwards the previous row's sample carries the link; upwards this one.
        let last = column.last;
        let adjacent = seq != 0 && column.next_row == seq;
        let linked = adjacent
            && if DOWN {
                last.down
            } else {
                cell.down && !last.filler
            };
        let end = signed_end::<DOWN>(out.v0..out.v1);
        let spanned = linked
            && between::<DOWN>(last.v, cell.v, end, |y, t| {
                out.put(column_index, y, &last.lerp(&cell, t))
            });
        let last_gap = if spanned {
            let gap = cell.v - last.v;
            if column.last_gap.is_nan() {
                reach_behind::<DOWN>(last.v, gap, end, |y| out.put(column_index, y, &last));
            }
            gap
        } else {
            column.close::<DOWN>(column_index, out);
            if adjacent {
                fill_column_crack::<DOWN>(self, column, &cell, column_index, end, out);
            }
            f32::NAN
        };
        columns.set(
            column_index,
            Column {
                last: cell,
                next_row: seq + 1,
                last_gap,
            },
        );
    }

    /// Draws the ends of the column runs still open after the last row. (A run a row
    /// does not continue is closed when its column's next sample comes: only that
    /// column's writes are ordered with it, so later is as good as at once.)
    fn close_columns<const DOWN: bool>(&self, columns: &Columns, out: &mut Output) {
        for index in 0..columns.len() {
            columns.get(index).close::<DOWN>(index, out);
        }
    }

    /// Pre-warps the source rows `rows`, visited downwards when `DOWN` (else upwards),
    /// into `out`.
    fn half<const DOWN: bool>(&self, rows: std::ops::Range<usize>, out: &mut Output) {
        let mut columns = Columns::new(self.columns);
        let mut samples = RowSamples::default();
        let linear = |a: &RowSample, b: &RowSample, _, t| a.cell.lerp(&b.cell, t);
        match self.variant {
            Variant::Interleaved => {
                for seq in 0..rows.len() {
                    let mut sink = IntoColumns::<DOWN> {
                        job: self,
                        columns: &mut columns,
                        out,
                        seq: seq as u32,
                    };
                    self.row(visited::<DOWN>(&rows, seq), linear, &mut sink, &mut samples);
                }
                self.close_columns::<DOWN>(&columns, out);
            }
            // (Its closed form is the orthographic warp's: a perspective texture's samples
            // blend linearly.)
            Variant::Compensated if !self.params.perspective() => {
                self.two_pass::<DOWN>(rows, &mut columns, &mut samples, out, |a, b, centre, _| {
                    compensated(a, b, centre, self.params)
                })
            }
            Variant::Compensated | Variant::OneD | Variant::Asymmetric => {
                self.two_pass::<DOWN>(rows, &mut columns, &mut samples, out, linear)
            }
        }
    }

    /// [`Job::half`] for the two-pass variants: the rows into an intermediate image,
    /// then its columns.
    fn two_pass<const DOWN: bool>(
        &self,
        rows: std::ops::Range<usize>,
        columns: &mut Columns,
        samples: &mut RowSamples,
        out: &mut Output,
        interpolate: impl Fn(&RowSample, &RowSample, f32, f32) -> Cell + Copy,
    ) {
        let mut intermediate: Vec<Option<Cell>> = vec![None; self.columns * rows.len()];
        for seq in 0..rows.len() {
            let mut sink = IntoRow {
                row: &mut intermediate[seq * self.columns..(seq + 1) * self.columns],
                u0: self.u0,
            };
            self.row(visited::<DOWN>(&rows, seq), interpolate, &mut sink, samples);
        }
        for seq in 0..rows.len() {
            let j = visited::<DOWN>(&rows, seq);
            for xi in 0..self.columns {
                let Some(cell) = intermediate[seq * self.columns + xi] else {
                    continue;
                };
                // (A crack's filler lands where the row pass put it, at the height of the
                // surface behind: a nearer one's own depth would not give it.)
                let v = match self.variant {
                    Variant::Asymmetric => cell.v,
                    _ if cell.filler => cell.v,
                    _ => self.params.warp_v(j as f32 + 0.5, cell.depth),
                };
                let x = xi as i64 + self.u0;
                self.push_column::<DOWN>(columns, out, x, Cell { v, ..cell }, seq as u32);
            }
        }
        self.close_columns::<DOWN>(columns, out);
    }
}

/// Pre-warps `impostor` for the eye of `params`, on the calling thread.
pub fn prewarp(impostor: &Impostor, params: &WarpParams, variant: Variant) -> PrewarpImage {
    prewarp_with(impostor, params, variant, None, false, true)
}

/// As [`prewarp`], with the halves above and below the epipole on two threads when
/// it visits at least twice `MIN_TASK_PIXELS` texels (each half about that): they
/// write disjoint rows (texels move towards the epipole or away from it, never past
/// it), so each
/// writes straight into the final image. With `seen` (see [`PlaneWindow::seen_by`]),
/// only the part of the image a texture mapping through that window reads is made,
/// from only the texels that can reach it — the same pixels there as without.
pub fn prewarp_split(
    impostor: &Impostor,
    params: &WarpParams,
    variant: Variant,
    seen: Option<&PlaneWindow>,
) -> PrewarpImage {
    prewarp_with(impostor, params, variant, seen, true, true)
}

fn prewarp_with(
    impostor: &Impostor,
    params: &WarpParams,
    variant: Variant,
    seen: Option<&PlaneWindow>,
    parallel: bool,
    lanes: bool,
) -> PrewarpImage {
    let c = &impostor.texture.camera;
    let (w, h) = (c.width as usize, c.height as usize);
    let Some(surface) = &impostor.surface else {
        return PrewarpImage::nothing_seen();
    };
    let ((mut u0, mut u1), (mut v0, mut v1)) = extent(params, surface, w as f32, h as f32);
    if u1 <= u0 || v1 <= v0 {
        // Every landing past the farthest an image reaches (`MAX_MARGIN`).
        return PrewarpImage::nothing_seen();
    }
    let (column_split, row_split) = (split_at(w, params.epipole.x), split_at(h, params.epipole.y));
    let (mut row_halves, mut rows) = ([0..column_split, column_split..w], [0..row_split, row_split..h]);
    // The scale factors' range: the table's ends (depth is linear in the level).
    let (first, last) = (params.scale.first().copied(), params.scale.last().copied());
    let scales = first.zip(last).map(|(a, b)| (a.min(b), a.max(b)));
    // `reaching` predicts landings exactly; the tables' rounding moves them by about
    // |e|·s·1e-7 texels, within its one-texel slack unless the epipole is millions of
    // texels away or s huge (a depth range reaching nearly to the eye): then every
    // texel is visited.
    let predictable =
        |(lo, hi): (f32, f32)| lo > 0.0 && hi <= 4.0 && params.epipole.abs().max_element() < 1e5;
    if let (Some(seen), Some(scales)) = (seen, scales.filter(|&s| predictable(s))) {
        // (Saturating: a window may reach far past the image.)
        u0 = u0.max((seen.u0.floor() as i32).saturating_sub(WINDOW_MARGIN));
        u1 = u1.min((seen.u1.ceil() as i32).saturating_add(WINDOW_MARGIN));
        v0 = v0.max((seen.v0.floor() as i32).saturating_sub(WINDOW_MARGIN));
        v1 = v1.min((seen.v1.ceil() as i32).saturating_add(WINDOW_MARGIN));
        if u1 <= u0 || v1 <= v0 {
            // The screen sees none of it.
            return PrewarpImage::nothing_seen();
        }
        let (e, cu, cv) = (params.epipole, (u0 as f32, u1 as f32), (v0 as f32, v1 as f32));
        row_halves = [
            reaching(0..column_split, true, e.x, scales, cu),
            reaching(column_split..w, false, e.x, scales, cu),
        ];
        rows = [
            reaching(0..row_split, true, e.y, scales, cv),
            reaching(row_split..h, false, e.y, scales, cv),
        ];
    }
    let (width, height) = ((u1 - u0).max(1) as usize, (v1 - v0).max(1) as usize);
    let mut texels = vec![PTexel::EMPTY; width * height];
    let job = Job {
        impostor,
        params,
        tables: Tables::of(params),
        variant,
        u0: u0 as i64,
        columns: width,
        row_halves,
        lanes,
        axes: Axes {
            a: c.a.normalize_or_zero(),
            b: c.b.normalize_or_zero(),
            f: c.f,
        },
        closed: impostor.faces == Faces::Front,
    };
    // Output rows whose centres lie above the epipole belong to the upper half.
    let split = ((params.epipole.y - 0.5).ceil() as i64 - v0 as i64).clamp(0, height as i64) as usize;
    let (upper, lower) = texels.split_at_mut(split * width);
    let mut upper = Output {
        texels: upper,
        v0: v0 as i64,
        v1: v0 as i64 + split as i64,
        width,
    };
    let mut lower = Output {
        texels: lower,
        v0: v0 as i64 + split as i64,
        v1: v0 as i64 + height as i64,
        width,
    };
    let [above, below] = rows;
    let visited = (above.clone().chain(below.clone()))
        .map(|j| job.row_texels(j).iter().map(|texels| texels.len()).sum::<usize>())
        .sum::<usize>();
    // Each half towards the epipole, or away from it (`outward`).
    let upper_half = |out: &mut Output| match params.outward {
        false => job.half::<true>(above.clone(), out),
        true => job.half::<false>(above.clone(), out),
    };
    let lower_half = |out: &mut Output| match params.outward {
        false => job.half::<false>(below.clone(), out),
        true => job.half::<true>(below.clone(), out),
    };
    if parallel && visited >= 2 * super::MIN_TASK_PIXELS {
        rayon::join(|| upper_half(&mut upper), || lower_half(&mut lower));
    } else {
        upper_half(&mut upper);
        lower_half(&mut lower);
    }
    PrewarpImage {
        u0,
        v0,
        width: width as u32,
        height: height as u32,
        texels,
        visited,
    }
}

/// The sample at pixel centre `centre` between row neighbours `a` and `b`, taken at the
/// point of the 3D segment between their surface points that pre-warps exactly there:
/// with `u(t) = u_a + t·Δu`, `d(t) = d_a + t·Δd` in the source, solve
/// `(u(t) + e1·k3·d(t)) / (1 + k3·d(t)) = centre` for `t` (an orthographic texture's
/// warp).
// (Always inlined: called, it returned its cell through memory, and the vector lerp's
// result read back piecewise stalled every pixel — 2.6× slower.)
#[inline(always)]
fn compensated(a: &RowSample, b: &RowSample, centre: f32, p: &WarpParams) -> Cell {
    let (k3, e1) = (p.k3, p.epipole.x);
    let (ad, bd) = (a.cell.depth, b.cell.depth);
    let (du, dd) = (b.source - a.source, bd - ad);
    let denominator = du + k3 * dd * (e1 - centre);
    let t = if denominator.abs() > 1e-12 {
        ((centre * (1.0 + k3 * ad) - a.source - e1 * k3 * ad) / denominator).clamp(0.0, 1.0)
    } else {
        0.5
    };
    a.cell.lerp(&b.cell, t)
}
