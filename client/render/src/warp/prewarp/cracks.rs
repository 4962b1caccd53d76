//! What fills a crack between two surfaces that part ([`Job::crack`]): the deeper, or
//! the nearer going on round past its outline ([`turns_away`]).

use glam::Vec3;

use super::spans::{between, half_gap};
use super::texel::Attributes;
use super::{Cell, Column, Job, Output};

/// How steeply a sample's surface must run away from the texture's plane, towards a
/// crack beside it, for the sample to count as lying at its surface's outline: depth per
/// unit across, 2 — its normal 63° or more from the texture's rays. (The knot's last
/// samples before an outline lie 10–15° short of grazing; a surface seen more nearly
/// face-on ends at an edge, where what goes on round is another face.) See
/// [`Job::crack_fillers`].
const OUTLINE_SLOPE: f32 = 2.0;

/// Whether the surface of a sample with `attributes` runs away from the plane of a
/// texture whose rays go along `f` at [`OUTLINE_SLOPE`] or more towards `toward` (a
/// unit direction in the plane): rounding out of the texture's sight that way. (Its
/// depth rises by `(n·toward)/|n·f|` per unit along `toward`, `n` its normal turned to
/// face the rays, as an encoded normal at a rim, rounded, may not. `f` is the rays'
/// direction of an orthographic texture, a closed surface's kind: a perspective one's
/// part from it.)
#[inline]
fn turns_away(attributes: Attributes, toward: Vec3, f: Vec3) -> bool {
    let n = attributes.normal_direction();
    let n = if n.dot(f) > 0.0 { -n } else { n };
    n.dot(toward) >= OUTLINE_SLOPE * -n.dot(f)
}

/// The crack between a column's last sample and `cell`, of another surface in the next
/// row ([`Job::crack`], itself out of line). (Inlined into the column step, though it
/// runs as often as [`Job::crack`]: called, it cost the pre-warp 4–20 % of its time for
/// about the same instructions — most where surfaces break often, as leaves do: the
/// tree's 256² texture at 5°, one core, 0.99 → 0.88 ms; the knot's 0.62 → 0.58. Once,
/// inlined, it made the row pass's span step a call instead and slowed the pre-warp:
/// `#[inline]` is a hint, so time both again when the column step grows.)
#[inline]
pub(super) fn fill_column_crack<const DOWN: bool>(
    job: &Job,
    column: &Column,
    cell: &Cell,
    column_index: usize,
    end: i64,
    out: &mut Output,
) {
    let last = (&column.last, column.last.v);
    job.crack::<DOWN>(
        job.axes.b,
        last,
        column.last_gap,
        (cell, cell.v),
        end,
        None,
        |y, filler| out.put(column_index, y, filler),
    );
}

impl Job<'_> {
    /// Between the end of a run (last sample `a`, landed at `a_at`, its run's last
    /// span `last_gap`, NaN when alone) and the next sample `b`, of another surface and
    /// ahead in the visit along `axis` (the texture's unit axis the visit runs along,
    /// forwards when `FORWARDS`): `put(pixel, filler)` for each pixel neither reaches —
    /// centres past `a`'s reach and at least half a pixel before `b` (a run's first
    /// sample reaches at most half a pixel behind it). Visited as in [`between`], up to
    /// `end`. (Once a break: not inlined.)
    ///
    /// What shows there from this eye is what lies behind the nearer surface's edge,
    /// which the texture never saw: it is drawn with the deeper of the two surfaces, as if
    /// that went on behind the nearer, or in part with the nearer going on round past its
    /// outline ([`Job::crack_fillers`]). Left empty, the sub-pixel parallax between a
    /// leaf's edge and the leaves behind it cracked the tree at every edge (its texture
    /// shown 0.2 % of its distance aside: 3–4 dB lost), and wider openings showed the sky
    /// through it. Filled, at any width — a partner texture, drawn behind, showed less
    /// there (the demo's median gap to geometry, 2–4 runs each: the tree −9.5 dB left
    /// empty, −7.4 to −7.6 filled up to 2 pixels wide, −5.2 to −5.5 up to 16, −4.8 to
    /// −5.2 at any width; the knot −0.9 to −1.3, −0.3 to −0.7, −0.2 to −0.5, −0.1 to
    /// −0.3).
    ///
    /// Where the deeper surface is known to end behind the nearer (`outline`: where its
    /// outline lands along the visit, [`Impostor::outlines`](crate::impostor::Impostor::outlines)),
    /// the deeper fills no pixel on the nearer's side of that: the eye sees past it
    /// there. (The nearer, going on round, still fills its half.)
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    pub(super) fn crack<const FORWARDS: bool>(
        &self,
        axis: Vec3,
        (a, a_at): (&Cell, f32),
        last_gap: f32,
        (b, b_at): (&Cell, f32),
        end: i64,
        outline: Option<f32>,
        mut put: impl FnMut(i64, &Cell),
    ) {
        let sign = if FORWARDS { 1.0 } else { -1.0 };
        // A sample alone draws the pixel it lands in; a run's end half its last span.
        let from = if last_gap.is_nan() {
            a_at.floor() + 0.5
        } else {
            a_at + half_gap(last_gap)
        };
        let middle = 0.5 * (a_at + b_at);
        // Along the visit, the way from the nearer to the deeper, and the deeper's depth.
        let towards_deeper = if b.depth > a.depth { sign } else { -sign };
        let deeper_depth = a.depth.max(b.depth);
        // (Worked out once a pixel needs them: most cracks have none.)
        let mut fillers = None;
        between::<FORWARDS>(from, b_at - 0.5 * sign, end, |x, _| {
            let [beside_a, beside_b] = fillers.get_or_insert_with(|| self.crack_fillers(a, b, axis * sign));
            let centre = x as f32 + 0.5;
            let beside = if (centre - middle) * sign <= 0.0 {
                beside_a
            } else {
                beside_b
            };
            // (Past the deeper surface's outline, on the nearer's side: nothing.)
            let past_outline = outline
                .is_some_and(|at| (centre - at) * towards_deeper < 0.0 && beside.depth == deeper_depth);
            if !past_outline {
                put(x, beside)
            }
        });
    }

    /// What fills a crack between `a`, the end of a run, and `b`, the next sample, of
    /// another surface, the visit going `toward` (a unit direction in the texture's
    /// plane): the pixels of the half beside `a`, then those of the half beside `b`
    /// ([`Job::crack`]). The deeper of the two, as a rule. But where the nearer one's
    /// surface, closed, rounds out of the texture's sight towards the other
    /// ([`turns_away`]: an outline, as where one loop of the knot passes in front of
    /// another), it goes on past its last sample, unsampled, and an eye turned to look
    /// round it sees it there before what lay behind it: the nearer fills the half
    /// beside it. (Where its outline lies between the two samples the texture cannot
    /// tell; halfway is the middle of the guesses. The deeper alone drew the loop in
    /// front thinned along its outline by up to 3 pixels, and toothed, seen 9.5° from
    /// the texture's eye.)
    #[inline]
    fn crack_fillers(&self, a: &Cell, b: &Cell, toward: Vec3) -> [Cell; 2] {
        let deeper = a.deeper(*b);
        let a_nearer = b.depth > a.depth;
        let (nearer, toward) = if a_nearer { (a, toward) } else { (b, -toward) };
        if !self.closed || !turns_away(nearer.attributes, toward, self.axes.f) {
            return [deeper; 2];
        }
        // (At the deeper one's height, as the rest of the crack: at the nearer's own, a
        // crack's pixels parted from their columns' others and left holes.)
        let nearer = Cell {
            down: false,
            filler: true,
            v: deeper.v,
            ..*nearer
        };
        if a_nearer {
            [nearer, deeper]
        } else {
            [deeper, nearer]
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{Vec2, Vec3};

    use super::super::{PTexel, Variant, prewarp};
    use crate::impostor::{Faces, Impostor};
    use crate::warp::params::WarpParams;

    /// A nearer surface's edge moving over the one behind it opens a crack the texture
    /// cannot show (it saw only the front); the pre-warp fills it with the surface
    /// behind. A square floating over a plane, seen from an eye moved diagonally so
    /// that the plane parts from the square's two edges nearer the epipole by a pixel
    /// or two: every pre-warped texel where the plane lands is drawn (fails with the
    /// cracks left empty: a 1–2-texel band along both edges), and those the square does
    /// not reach show the plane (fails filling with the nearer surface).
    #[test]
    fn cracks_behind_a_nearer_edge_show_the_surface_behind() {
        use crate::fixtures::{EYE, PLANE, square_over_plane};
        let n = 32;
        let (plane, square) = (PLANE, ([0, 255, 0], 40));
        let impostor = Impostor::new(square_over_plane(n, 10..22, square));
        // The eye moved towards the plane's lower left until the plane parts from the
        // square's left edge by more than a texel.
        let parted = |params: &WarpParams| {
            params.warp(10.5, 16.0, square.1 as usize).x - params.warp(9.5, 16.0, plane.1 as usize).x - 1.0
        };
        let params = (1..100)
            .map(|step| {
                let moved = EYE + Vec3::new(-1.0, -1.0, 0.0) * 0.1 * step as f32;
                WarpParams::new(&impostor.texture, moved).expect("params")
            })
            .find(|params| parted(params) > 1.2)
            .expect("an eye that opens a crack");
        let image = prewarp(&impostor, &params, Variant::Interleaved);
        let landing = |level: u16, lo: f32, hi: f32| {
            let (a, b) = (
                params.warp(lo, lo, level as usize),
                params.warp(hi, hi, level as usize),
            );
            (a.min(b), a.max(b))
        };
        let (plane_lo, plane_hi) = landing(plane.1, 0.0, n as f32);
        let (square_lo, square_hi) = landing(square.1, 10.0, 22.0);
        let (mut holes, mut smeared) = (0, 0);
        for y in 0..image.height {
            for x in 0..image.width {
                let centre = Vec2::new((image.u0 + x as i32) as f32, (image.v0 + y as i32) as f32) + 0.5;
                let texel = image.texels[(y * image.width + x) as usize];
                let within = |lo: Vec2, hi: Vec2, margin: f32| {
                    centre.cmpge(lo - margin).all() && centre.cmple(hi + margin).all()
                };
                if within(plane_lo, plane_hi, -1.0) && texel.is_empty() {
                    holes += 1;
                }
                if texel.attributes.albedo() == square.0 && !within(square_lo, square_hi, 1.0) {
                    smeared += 1;
                }
            }
        }
        assert_eq!(
            (holes, smeared),
            (0, 0),
            "holes, square texels outside the square"
        );
    }

    /// Where the texture knows the surface behind a nearer edge ends behind it
    /// ([`Impostor::outlines`], from its hidden-surface list), a crack opening at that
    /// edge is filled from the surface behind no nearer the edge than where its outline
    /// lands; between the two the image stays empty, for what lies beyond. The square
    /// over the plane, its right edge's rows told that the plane ends a texel in behind
    /// it, the eye moved until the plane parts from that edge by 6 pixels or more: in
    /// each of those rows, the crack's pixels short of the outline's landing are empty
    /// and those past it show the plane (fails filled throughout, as it is without the
    /// list: checked too).
    #[test]
    fn a_crack_is_filled_no_nearer_than_the_outline_behind_it() {
        use crate::fixtures::{EYE, PLANE, square_over_plane};
        use relief_core::relief::Hidden;
        let (plane, square) = (PLANE, ([0, 255, 0], 40));
        let mut texture = square_over_plane(32, 10..22, square);
        let rows = 12..20u32;
        texture.hidden = rows
            .clone()
            .map(|j| Hidden {
                texel: j * 32 + 21,
                side: 1,
                inward: 1,
                depth: plane.1,
            })
            .collect();
        texture.check_hidden().expect("well formed");
        let told = Impostor::new(texture.clone());
        let untold = Impostor {
            outlines: Default::default(),
            ..told.clone()
        };
        assert!(!told.outlines.is_empty(), "the list read");
        let c = texture.camera;
        // Where the square's right edge, the plane beside it and the plane's outline (at
        // texel 20 of the row) land along row `j`.
        let landings = |params: &WarpParams, j: u32| {
            let at = |i: f32, level: u16| params.warp(i, j as f32 + 0.5, level as usize).x;
            (at(21.5, square.1), at(22.5, plane.1), at(20.5, plane.1))
        };
        let params = (1..200)
            .map(|step| EYE + (c.a.normalize() + c.b.normalize()) * 0.1 * step as f32)
            .map(|eye| WarpParams::new(&told.texture, eye).expect("params"))
            .find(|params| {
                let (edge, plane_at, _) = landings(params, 16);
                plane_at - edge > 6.0
            })
            .expect("an eye that opens a crack");
        for (impostor, outlines_known) in [(&told, true), (&untold, false)] {
            let image = prewarp(impostor, &params, Variant::Interleaved);
            let (mut empty, mut filled, mut past_outline) = (0, 0, 0);
            for j in rows.clone().skip(1).take(6) {
                let (edge, plane_at, outline) = landings(&params, j);
                assert!(
                    edge + 1.0 < outline && outline + 1.0 < plane_at,
                    "row {j}: {edge} {outline} {plane_at}"
                );
                // The row lands at the plane's height there.
                let v = params.warp(22.5, j as f32 + 0.5, plane.1 as usize).y;
                for x in (edge.ceil() as i32 + 1)..(plane_at.floor() as i32) {
                    let centre = x as f32 + 0.5;
                    if (centre - outline).abs() < 1.0 {
                        continue;
                    }
                    let texel = image.at(centre, v).copied().unwrap_or(PTexel::EMPTY);
                    match (centre < outline, texel.is_empty()) {
                        (true, true) => empty += 1,
                        (true, false) => filled += 1,
                        (false, false) => past_outline += 1,
                        (false, true) => panic!("row {j}: a hole past the outline at {centre}"),
                    }
                }
            }
            assert!(past_outline > 0, "pixels past the outline");
            if outlines_known {
                assert!(
                    empty > 0 && filled == 0,
                    "{empty} empty, {filled} filled short of the outline"
                );
            } else {
                assert!(
                    empty == 0 && filled > 0,
                    "without the list: {empty} empty, {filled} filled"
                );
            }
        }
    }

    /// Where a closed surface's last samples run out of the texture's sight towards the
    /// crack — an outline, as of a box with rounded edges standing over the plane — the
    /// nearer fills the half of the crack beside it, the plane the rest; a sheet's edge
    /// may be where it ends, and the plane fills it all. The square of the test above
    /// with one edge's normals turned 70° outwards, each edge in turn (the row pass's
    /// cracks either way, the column pass's either way), the eye moved until the plane
    /// parts from that edge by 5 pixels or more: every pixel of the crack between the
    /// square's last sample and the plane's first shows the square in the half beside
    /// the square (closed) and the plane in the other, and the plane throughout as a
    /// sheet (fails with the deeper filling it all, the nearer, or a crack's pixels at
    /// the nearer's height) — interleaved, and with the column pass apart (`OneD`).
    #[test]
    fn outline_cracks_show_a_closed_surface_going_on_round() {
        use crate::fixtures::{EYE, PLANE, square_over_plane};
        use relief_core::relief::encode_normal_rgb8;
        let (plane, square) = (PLANE, ([0, 255, 0], 40));
        // Each edge: a texel of it at `along` = 16, the step outwards to the plane.
        for (edge, out) in [
            ("left", (-1, 0)),
            ("right", (1, 0)),
            ("top", (0, -1)),
            ("bottom", (0, 1)),
        ] {
            let mut texture = square_over_plane(32, 10..22, square);
            let c = texture.camera;
            let outwards = (c.a.normalize() * out.0 as f32 + c.b.normalize() * out.1 as f32).normalize();
            let turned = (-c.f * 70f32.to_radians().cos() + outwards * 70f32.to_radians().sin()).normalize();
            // The edge's texel `along` its length (clear of the corners).
            let texel = |along: i32| match out {
                (0, dj) => (along, if dj < 0 { 10 } else { 21 }),
                (di, _) => (if di < 0 { 10 } else { 21 }, along),
            };
            for along in 12..20 {
                let (i, j) = texel(along);
                let k = texture.index(i as u32, j as u32);
                texture.normal[k] = encode_normal_rgb8(turned);
            }
            let sheet = Impostor::new(texture);
            // Where the edge's texel `along` and the plane's beyond it land.
            let landings = |params: &WarpParams, along: i32| {
                let (i, j) = texel(along);
                let centre =
                    |i: i32, j: i32, level: u16| params.warp(i as f32 + 0.5, j as f32 + 0.5, level as usize);
                (centre(i, j, square.1), centre(i + out.0, j + out.1, plane.1))
            };
            let outward = Vec2::new(out.0 as f32, out.1 as f32);
            // The eye moved outwards, to see round the edge; past a side edge also down its
            // length, so that a row's crack parts the plane's height from the square's
            // (past a top or bottom edge, that would slide the plane's columns past the
            // square's, and a column's samples come from both).
            let aside = if out.1 == 0 { c.b.normalize() } else { Vec3::ZERO };
            let params = (1..200)
                .map(|step| EYE + (outwards + aside) * 0.1 * step as f32)
                .map(|eye| WarpParams::new(&sheet.texture, eye).expect("params"))
                .find(|params| {
                    let (square_at, plane_at) = landings(params, 16);
                    (plane_at - square_at).dot(outward) > 5.0
                })
                .expect("an eye that opens a crack");
            for variant in [Variant::Interleaved, Variant::OneD] {
                for closed in [true, false] {
                    let impostor = match closed {
                        true => sheet.clone().with_faces(Faces::Front),
                        false => sheet.clone(),
                    };
                    let image = prewarp(&impostor, &params, variant);
                    let (mut beside_square, mut beside_plane) = (0, 0);
                    for along in 13..19 {
                        let (square_at, plane_at) = landings(&params, along);
                        // Along the crack (x for a row's, y for a column's) and across it:
                        // a row's crack lands at the plane's height, a column's in the
                        // column between the two.
                        let (lengthwise, (from, to), across) = match out {
                            (_, 0) => (true, (square_at.x, plane_at.x), plane_at.y.floor() as i32),
                            _ => (false, (square_at.y, plane_at.y), square_at.x.floor() as i32),
                        };
                        let middle = 0.5 * (from + to);
                        let (lo, hi) = (from.min(to) + 0.75, from.max(to) - 0.75);
                        for at in (lo.ceil() as i32 - 1)..=(hi.floor() as i32) {
                            let centre = at as f32 + 0.5;
                            if centre < lo || centre > hi || (centre - middle).abs() < 0.25 {
                                continue;
                            }
                            let (x, y) = if lengthwise { (at, across) } else { (across, at) };
                            let (x, y) = (x - image.u0, y - image.v0);
                            let albedo = image.texels[(y * image.width as i32 + x) as usize]
                                .attributes
                                .albedo();
                            // (Nearer the square's landing than the plane's.)
                            let beside = (centre - from).abs() < (centre - to).abs();
                            let want = if closed && beside { square.0 } else { plane.0 };
                            let what = format!("{edge} edge, {variant:?}, closed {closed}, texel {along}");
                            assert_eq!(
                                albedo, want,
                                "{what}: centre {centre}, square at {from}, plane at {to}"
                            );
                            match beside {
                                true => beside_square += 1,
                                false => beside_plane += 1,
                            }
                        }
                    }
                    assert!(
                        beside_square > 0 && beside_plane > 0,
                        "{edge}, {variant:?}: {beside_square} {beside_plane}"
                    );
                }
            }
        }
    }
}
