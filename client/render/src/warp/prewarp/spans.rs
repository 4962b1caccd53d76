//! The order of the pre-warp's visit — each half of an axis ([`split_at`]) from the
//! border towards the epipole, or outwards ([`visited`], [`signed_end`]) — the pixels
//! between two samples along an axis, visited either way ([`between`]), and how far a
//! run of samples reaches past its ends ([`reach_ahead`], [`reach_behind`]).

/// Along an axis visited forwards (`FORWARDS`: increasing coordinates) or backwards:
/// when `b` is not behind `a`, calls `each(pixel, t)` for every pixel up to `end` whose
/// centre lies in `(a, b]`, in visiting order, `t` being the centre's linear position
/// from `a` to `b`, and returns true; returns false when `b` folds back behind `a` (or
/// either is NaN). `end` is the image's last pixel along the axis in the
/// visiting direction, in the signed coordinates below ([`signed_end`]).
///
/// A backwards visit runs on negated coordinates, where pixel `x` is pixel `−x − 1`:
/// one test and one loop serve both directions, and the direction, a const, costs no
/// branch per sample.
#[inline(always)]
pub(super) fn between<const FORWARDS: bool>(
    a: f32,
    b: f32,
    end: i64,
    mut each: impl FnMut(i64, f32),
) -> bool {
    let sign = if FORWARDS { 1.0 } else { -1.0 };
    let (a, b) = (a * sign, b * sign);
    // (False for NaN too; positions are finite, `WarpParams` sees to that.)
    let ahead = b >= a;
    if !ahead {
        return false;
    }
    let (below_a, below_b) = ((a - 0.5).floor(), (b - 0.5).floor());
    // No pixel centre between them (common where the pre-warp compresses the
    // surface): no division, no conversions.
    if below_a == below_b {
        return true;
    }
    // (Finite: samples that coincide have no centre between them, returned above.)
    let inv = 1.0 / (b - a);
    // Samples move ahead in the visit (towards the epipole, or outwards away from it):
    // a far one makes spans run far past the image on that side (never before it), cut
    // at its end.
    let first = (below_a as i64).saturating_add(1);
    let last = (below_b as i64).min(end);
    // (Half-open ranges: `..=` iterates measurably slower here.)
    for x in first..last + 1 {
        let t = ((x as f32 + 0.5 - a) * inv).clamp(0.0, 1.0);
        each(if FORWARDS { x } else { -x - 1 }, t);
    }
    true
}

/// Half of a span `gap` long (signed), at most half a pixel of the pre-warped image: how
/// far a run's end sample reaches past it. (A sample alone covers about one pixel; a
/// longer reach, at a stretched end, drew spikes past the silhouette.)
#[inline(always)]
pub(super) fn half_gap(gap: f32) -> f32 {
    0.5 * gap.clamp(-1.0, 1.0)
}

/// A run's last sample, landing at `pos`, draws its share ahead of it: with `put(pixel)`,
/// the pixel it lands in when the run has no span (`last_gap` NaN: the sample is alone),
/// else the pixels within half of the run's last span, `last_gap`, ahead ([`half_gap`]).
/// Visited as in [`between`], up to `end`. (Once a run, not per sample: kept out of the
/// passes' inlined code, whose every pixel is a column step.)
#[inline(never)]
pub(super) fn reach_ahead<const FORWARDS: bool>(pos: f32, last_gap: f32, end: i64, mut put: impl FnMut(i64)) {
    if last_gap.is_nan() {
        put(pos.floor() as i64);
        return;
    }
    between::<FORWARDS>(pos, pos + half_gap(last_gap), end, |x, _| put(x));
}

/// A run's first sample, landing at `pos`, draws its share behind it once the run's
/// first span, `gap`, is known: the pixels within half of it ([`half_gap`]). (Once a
/// run: not inlined.)
#[inline(never)]
pub(super) fn reach_behind<const FORWARDS: bool>(pos: f32, gap: f32, end: i64, mut put: impl FnMut(i64)) {
    between::<FORWARDS>(pos - half_gap(gap), pos, end, |x, _| put(x));
}

/// The last pixel of `pixels` met visiting forwards (`FORWARDS`) or backwards, in
/// [`between`]'s signed coordinates (pixel `x` is `−x − 1` backwards).
#[inline(always)]
pub(super) fn signed_end<const FORWARDS: bool>(pixels: std::ops::Range<i64>) -> i64 {
    if FORWARDS {
        pixels.end - 1
    } else {
        -pixels.start - 1
    }
}

/// The `k`-th of `cells` visited forwards (`FORWARDS`) or backwards.
#[inline(always)]
pub(super) fn visited<const FORWARDS: bool>(cells: &std::ops::Range<usize>, k: usize) -> usize {
    if FORWARDS {
        cells.start + k
    } else {
        cells.end - 1 - k
    }
}

/// The number of cells of `0..n` (centres at `k + 0.5`) before the epipole `e`: the
/// pre-warp visits each half towards the epipole (or, outwards, away from it).
#[inline]
pub(super) fn split_at(n: usize, e: f32) -> usize {
    (e - 0.5).ceil().clamp(0.0, n as f32) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    fn visits<const FORWARDS: bool>(a: f32, b: f32, end: i64) -> (bool, Vec<i64>) {
        let mut pixels = Vec::new();
        let spanned = between::<FORWARDS>(a, b, end, |x, t| {
            assert!((0.0..=1.0).contains(&t), "t = {t}");
            pixels.push(x);
        });
        (spanned, pixels)
    }

    /// The pixels whose centres lie in `(a, b]`, in visiting order, cut at the image's
    /// end, for both directions; folds and NaN span nothing.
    #[test]
    fn spans_visit_the_centres_between_two_samples() {
        assert_eq!(visits::<true>(2.2, 5.5, 100), (true, vec![2, 3, 4, 5]));
        assert_eq!(visits::<true>(2.6, 2.9, 100), (true, vec![]));
        // Backwards: from u = 5.5 down to 2.2, pixel 5's centre (5.5) excluded.
        let end = signed_end::<false>(0..100);
        assert_eq!(visits::<false>(5.5, 2.2, end), (true, vec![4, 3, 2]));
        assert_eq!(visits::<true>(5.0, 4.0, 100), (false, vec![]));
        assert_eq!(visits::<true>(f32::NAN, 4.0, 100), (false, vec![]));
        // A sample a billion pixels away (an epipole far off): cut at the end, 0..=9.
        assert_eq!(visits::<true>(0.2, 1e9, 9).1, (0..10).collect::<Vec<_>>());
        let end = signed_end::<false>(-10..50);
        assert_eq!(
            visits::<false>(3.7, -1e9, end).1,
            (-10..4).rev().collect::<Vec<_>>()
        );
    }
}
