//! Image error of a rendered frame against a reference frame, over a region.

use relief_core::frame::{Frame, NO_OBJECT};

/// A frame whose covered pixels differ from its reference's in more than this fraction
/// of the pixels either covers is marked ([`ImageError::covers_reference`]): its PSNR
/// over the pixels both show judges too little of it to be ranked. (Every method drawing
/// correctly differs from it at silhouettes only: under 6 % at 5°, the test
/// `every_method_follows_a_turned_eye`.)
pub const MAX_HOLE_FRAC: f64 = 0.1;

/// Error figures of a frame against a reference.
///
/// Shading error and coverage error are kept apart — PSNR and SSIM are measured on the
/// pixels where both frames show the object, and `hole_frac` counts the pixels where
/// only one of them does (holes, or wrongly filled pixels) among those where either
/// does — and taken together in `psnr_whole_db`, over every pixel either shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageError {
    /// Peak signal-to-noise ratio over RGB, dB, over the pixels both frames cover
    /// (`INFINITY` when identical; NaN when no pixel is covered by both: nothing to
    /// compare).
    pub psnr_db: f64,
    /// PSNR over every pixel either frame covers: what the frame leaves empty, or
    /// fills where the reference has nothing, counts as the error it is (NaN when
    /// neither covers a pixel).
    pub psnr_whole_db: f64,
    /// Mean SSIM of the luma over 8×8 windows holding pixels both frames cover (NaN
    /// when there are none).
    pub ssim: f64,
    /// Fraction of covered pixels that only one frame covers.
    pub hole_frac: f64,
    /// Pixels both frames cover.
    pub pixels: usize,
}

impl ImageError {
    /// Whether the frame covers what the reference does but for at most
    /// [`MAX_HOLE_FRAC`]: only then does `psnr_db` speak for the frame.
    pub fn covers_reference(&self) -> bool {
        self.hole_frac <= MAX_HOLE_FRAC
    }
}

/// Writes a PSNR for JSON: a number; `"inf"` for identical images, since JSON has no
/// infinity and `null` is what "nothing to compare" (NaN) writes. Use with
/// `#[serde(serialize_with = "serialize_psnr")]`.
pub fn serialize_psnr<S: serde::Serializer>(db: &f64, s: S) -> Result<S::Ok, S::Error> {
    if *db == f64::INFINITY {
        s.serialize_str("inf")
    } else {
        s.serialize_f64(*db)
    }
}

/// Compares `frame` with `reference` for `object` (or, with `None`, any object). Both
/// frames must be the same size.
pub fn compare(frame: &Frame, reference: &Frame, object: Option<u32>) -> ImageError {
    let region = Region::of(frame, reference, object);
    ImageError {
        psnr_db: psnr(region.squared_both, region.both),
        psnr_whole_db: psnr(region.squared_either, region.either),
        ssim: ssim(frame, reference, &region.mask),
        hole_frac: region.mismatched as f64 / region.either.max(1) as f64,
        pixels: region.both,
    }
}

/// The pixels of `frame` and `reference` showing the object, and their squared error.
struct Region {
    /// Per pixel: both show it.
    mask: Vec<bool>,
    both: usize,
    either: usize,
    mismatched: usize,
    squared_both: f64,
    squared_either: f64,
}

impl Region {
    fn of(frame: &Frame, reference: &Frame, object: Option<u32>) -> Region {
        assert_same_size(frame, reference);
        let shows = |id: u32| match object {
            Some(k) => id == k,
            None => id != NO_OBJECT,
        };
        let mut region = Region {
            mask: Vec::with_capacity(frame.object.len()),
            both: 0,
            either: 0,
            mismatched: 0,
            squared_both: 0.0,
            squared_either: 0.0,
        };
        for (k, (&a, &b)) in frame.object.iter().zip(&reference.object).enumerate() {
            let (a, b) = (shows(a), shows(b));
            region.mask.push(a && b);
            if !(a || b) {
                continue;
            }
            let squared = squared_error(frame, reference, k);
            region.either += 1;
            region.squared_either += squared;
            if a && b {
                region.both += 1;
                region.squared_both += squared;
            } else {
                region.mismatched += 1;
            }
        }
        region
    }
}

/// PSNR over RGB from the summed squared error of `pixels` pixels (`INFINITY` when
/// there is no error, NaN when there are no pixels: an empty comparison is no match).
fn psnr(squared: f64, pixels: usize) -> f64 {
    if pixels == 0 {
        return f64::NAN;
    }
    let mse = squared / (3 * pixels) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// PSNR of `object`'s image: over every pixel where either frame shows it, so that
/// what its silhouette gets wrong counts along with its shading
/// ([`ImageError::psnr_whole_db`]). `None` when neither frame shows it.
pub fn object_psnr(frame: &Frame, reference: &Frame, object: u32) -> Option<f64> {
    let region = Region::of(frame, reference, Some(object));
    (region.either > 0).then(|| psnr(region.squared_either, region.either))
}

/// Both frames must be the same size: comparing others is a bug of the caller.
fn assert_same_size(frame: &Frame, reference: &Frame) {
    assert_eq!(
        (frame.width, frame.height),
        (reference.width, reference.height),
        "frames to compare differ in size"
    );
}

/// The squared RGB error of pixel `k`, summed over the channels.
fn squared_error(frame: &Frame, reference: &Frame, k: usize) -> f64 {
    (0..3)
        .map(|c| {
            let d = frame.color[k][c] as f64 - reference.color[k][c] as f64;
            d * d
        })
        .sum()
}

/// Mean SSIM (Wang et al. 2004, constants K1 = 0.01, K2 = 0.03) of Rec. 601 luma over
/// non-overlapping 8×8 windows that contain at least one region pixel; pixels outside
/// the region take the reference's value in both images, so only the region is judged.
fn ssim(a: &Frame, b: &Frame, region: &[bool]) -> f64 {
    const WINDOW: usize = 8;
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let luma = |f: &Frame, k: usize| {
        let [r, g, b] = f.color[k];
        0.299 * r as f64 + 0.587 * g as f64 + 0.114 * b as f64
    };
    let (w, h) = (a.width as usize, a.height as usize);
    let (mut total, mut windows) = (0f64, 0usize);
    for wy in (0..h).step_by(WINDOW) {
        for wx in (0..w).step_by(WINDOW) {
            let cells: Vec<usize> = (wy..(wy + WINDOW).min(h))
                .flat_map(|y| (wx..(wx + WINDOW).min(w)).map(move |x| y * w + x))
                .collect();
            if !cells.iter().any(|&k| region[k]) {
                continue;
            }
            let n = cells.len() as f64;
            let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for &k in &cells {
                let y = luma(b, k);
                let x = if region[k] { luma(a, k) } else { y };
                sa += x;
                sb += y;
                saa += x * x;
                sbb += y * y;
                sab += x * y;
            }
            let (ma, mb) = (sa / n, sb / n);
            let (va, vb, cov) = (saa / n - ma * ma, sbb / n - mb * mb, sab / n - ma * mb);
            total += ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
            windows += 1;
        }
    }
    if windows == 0 {
        f64::NAN
    } else {
        total / windows as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(color: [u8; 3], object: u32) -> Frame {
        let mut f = Frame::new(16, 16, [0, 0, 0]);
        for k in 0..64 {
            f.color[k] = color;
            f.object[k] = object;
        }
        f
    }

    #[test]
    fn identical_frames_are_perfect() {
        let a = frame([100, 150, 200], 0);
        let e = compare(&a, &a, Some(0));
        assert_eq!(e.psnr_db, f64::INFINITY);
        assert!((e.ssim - 1.0).abs() < 1e-12);
        assert_eq!(e.hole_frac, 0.0);
        assert_eq!(e.pixels, 64);
    }

    #[test]
    fn known_error_gives_known_psnr() {
        let a = frame([100, 150, 200], 0);
        let b = frame([110, 160, 210], 0);
        // MSE 100 → PSNR = 10·log10(255²/100) = 28.13 dB.
        let e = compare(&a, &b, Some(0));
        assert!((e.psnr_db - 28.1308).abs() < 1e-3, "{}", e.psnr_db);
        // A frame without the object has nothing to compare: all holes, no PSNR or
        // SSIM (NaN), never a perfect score.
        let missing = frame([0, 0, 0], NO_OBJECT);
        let e = compare(&missing, &a, Some(0));
        assert_eq!((e.hole_frac, e.pixels), (1.0, 0));
        assert!(e.psnr_db.is_nan() && e.ssim.is_nan(), "{e:?}");
    }

    #[test]
    fn object_psnr_counts_the_silhouette() {
        let a = frame([100, 150, 200], 0);
        assert_eq!(object_psnr(&a, &a, 0), Some(f64::INFINITY));
        assert_eq!(object_psnr(&a, &a, 7), None);
        // Half the object missing (background black): the 32 missing pixels count.
        let mut b = a.clone();
        for k in 32..64 {
            b.color[k] = [0, 0, 0];
            b.object[k] = NO_OBJECT;
        }
        let squared = 32.0 * (100f64.powi(2) + 150f64.powi(2) + 200f64.powi(2));
        let expected = 10.0 * (255f64.powi(2) * 3.0 * 64.0 / squared).log10();
        let got = object_psnr(&b, &a, 0).unwrap();
        assert!((got - expected).abs() < 1e-9, "{got} vs {expected}");
        // … which compare leaves to hole_frac, and counts in its whole figure.
        let e = compare(&b, &a, Some(0));
        assert_eq!(e.psnr_db, f64::INFINITY);
        assert!((e.psnr_whole_db - expected).abs() < 1e-9, "{e:?}");
        assert_eq!(e.hole_frac, 0.5);
    }

    /// A frame that draws a sparse grid of exact pixels (8 % of the object) scores a
    /// perfect PSNR where both show, but it is marked as not covering the reference,
    /// and its whole figure ranks it far below a frame that covers everything with a
    /// small error.
    #[test]
    fn a_sparse_frame_never_outranks_one_that_covers() {
        let reference = frame([100, 150, 200], 0);
        let mut dots = reference.clone();
        for k in 0..64 {
            if k % 12 != 0 {
                dots.color[k] = [0, 0, 0];
                dots.object[k] = NO_OBJECT;
            }
        }
        let close = frame([103, 153, 203], 0);
        let (dots, close) = (
            compare(&dots, &reference, Some(0)),
            compare(&close, &reference, Some(0)),
        );
        assert!(dots.hole_frac > 0.9 && !dots.covers_reference(), "{dots:?}");
        assert!(close.covers_reference(), "{close:?}");
        // Over the pixels both show the dots are perfect, the covering frame is not:
        // that figure alone would rank them the wrong way round.
        assert!(dots.psnr_db > close.psnr_db, "{dots:?} {close:?}");
        assert!(
            close.psnr_whole_db > dots.psnr_whole_db + 20.0,
            "{dots:?} {close:?}"
        );
    }
}
