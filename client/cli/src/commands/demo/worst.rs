//! Each object's worst compared frame as a picture to look at: the object cropped from
//! the frame as drawn, the anti-aliased reference and exact geometry, side by side and
//! enlarged (`worst_OBJECT.png`) — where its paired gap to exact geometry was lowest.

use std::path::Path;

use anyhow::{Context, Result};

use relief_core::frame::Frame;

/// Pixels of context kept round the object's box.
const MARGIN: u32 = 6;
/// A crop is enlarged by the largest whole factor up to this (single pixels must be
/// seen) that keeps its longer side within [`PANEL_SIDE`] pixels; one already longer
/// stays at one pixel a pixel.
const MAX_SCALE: u32 = 4;
/// Three panels this wide fit a screen side by side.
const PANEL_SIDE: u32 = 360;
/// White between the panels, so that the eye finds their edges.
const GAP: u32 = 4;

/// The box `(x0, y0, x1, y1)` (exclusive ends) holding every pixel of `object` in any
/// of `frames` (all of one size), grown by [`MARGIN`] within the frame; `None` where
/// none shows it.
fn object_box(frames: &[&Frame], object: u32) -> Option<(u32, u32, u32, u32)> {
    let (w, h) = (frames[0].width, frames[0].height);
    let mut found: Option<(u32, u32, u32, u32)> = None;
    for frame in frames {
        for (i, _) in frame.object.iter().enumerate().filter(|&(_, &o)| o == object) {
            let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
            found = Some(match found {
                None => (x, y, x + 1, y + 1),
                Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1)),
            });
        }
    }
    found.map(|(x0, y0, x1, y1)| {
        (
            x0.saturating_sub(MARGIN),
            y0.saturating_sub(MARGIN),
            (x1 + MARGIN).min(w),
            (y1 + MARGIN).min(h),
        )
    })
}

/// `panels` (the frame as drawn, the reference, exact geometry) cropped round `object`
/// and set side by side, enlarged; `None` where no panel shows it.
pub(super) fn side_by_side(panels: [&Frame; 3], object: u32) -> Option<Frame> {
    let (x0, y0, x1, y1) = object_box(&panels, object)?;
    let (cw, ch) = (x1 - x0, y1 - y0);
    let scale = (PANEL_SIDE / cw.max(ch)).clamp(1, MAX_SCALE);
    let (pw, ph) = (cw * scale, ch * scale);
    let mut out = Frame::new(3 * pw + 2 * GAP, ph, [255; 3]);
    for (p, panel) in panels.iter().enumerate() {
        let left = p as u32 * (pw + GAP);
        for y in 0..ph {
            for x in 0..pw {
                let source = ((y0 + y / scale) * panel.width + x0 + x / scale) as usize;
                out.color[(y * out.width + left + x) as usize] = panel.color[source];
            }
        }
    }
    Some(out)
}

/// Writes [`side_by_side`] as `dir/worst_OBJECT.png` (`name` already fit for a file
/// name).
pub(super) fn save(dir: &Path, name: &str, picture: &Frame) -> Result<()> {
    let path = dir.join(format!("worst_{name}.png"));
    picture
        .save_png(&path)
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The crop holds the object's pixels from every panel, with the margin, and each
    /// panel's pixel lands in its own third, enlarged.
    #[test]
    fn the_crop_holds_the_object_in_every_panel() {
        let mut drawn = Frame::new(100, 50, [0; 3]);
        let mut reference = Frame::new(100, 50, [10; 3]);
        let geometry = Frame::new(100, 50, [20; 3]);
        drawn.object[20 * 100 + 30] = 7;
        drawn.color[20 * 100 + 30] = [200, 0, 0];
        reference.object[24 * 100 + 40] = 7;
        assert_eq!(
            object_box(&[&drawn, &reference, &geometry], 7),
            Some((24, 14, 47, 31))
        );
        assert_eq!(object_box(&[&geometry], 7), None);
        let picture = side_by_side([&drawn, &reference, &geometry], 7).expect("shown");
        // 23 × 17 pixels, enlarged 4 times.
        assert_eq!((picture.width, picture.height), (3 * 92 + 2 * GAP, 68));
        let at = |x: u32, y: u32| picture.color[(y * picture.width + x) as usize];
        // The drawn pixel (30, 20) is (6, 6) in the crop: (24..28, 24..28) in the first panel.
        assert_eq!(at(24, 24), [200, 0, 0]);
        assert_eq!(at(27, 27), [200, 0, 0]);
        assert_eq!(at(28, 24), [0; 3]);
        // Each panel from its own frame, white between them.
        assert_eq!(at(92 + GAP + 24, 24), [10; 3]);
        assert_eq!(at(2 * (92 + GAP) + 24, 24), [20; 3]);
        assert_eq!(at(92, 0), [255; 3]);
    }
}
