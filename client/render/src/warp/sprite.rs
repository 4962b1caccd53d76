//! The sprite stage (Schaufler's stage 1): while the eye has moved less than a pixel's
//! worth, the last displayed impostor is reused as it is.

use crate::gbuffer::{Fragment, GBuffer, Stored};

/// A rectangle of displayed impostor pixels, kept to be drawn again.
#[derive(Debug, Clone, PartialEq)]
pub struct Sprite {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    /// Row-major, exactly as the buffer held them (so a redraw is identical); `None`
    /// where the object was not.
    pixels: Vec<Option<(f32, Stored)>>,
    /// The object's silhouette fragments, and the width of the buffer they index.
    fragments: Vec<Fragment>,
    buffer_width: u32,
}

impl Sprite {
    /// Keeps the pixels of `object` from `gbuffer` (the bounding rectangle of them), and
    /// its fragments.
    pub fn capture(gbuffer: &GBuffer, object: u32) -> Option<Sprite> {
        Self::capture_in(gbuffer, object, (0, 0, gbuffer.width, gbuffer.height))
    }

    /// As [`Sprite::capture`], looking only inside the screen rectangle
    /// `(x0, y0, x1, y1)` (exclusive ends) where the object can be.
    pub fn capture_in(gbuffer: &GBuffer, object: u32, rect: (u32, u32, u32, u32)) -> Option<Sprite> {
        let w = gbuffer.width as usize;
        let (rx0, ry0) = (rect.0 as usize, rect.1 as usize);
        let (rx1, ry1) = (
            (rect.2 as usize).min(w),
            (rect.3 as usize).min(gbuffer.height as usize),
        );
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        let fragments: Vec<Fragment> = gbuffer.fragments_of(object).copied().collect();
        for y in ry0..ry1 {
            for x in rx0..rx1 {
                if gbuffer.object_at(x as u32, y as u32) == object {
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x + 1);
                    y1 = y1.max(y + 1);
                }
            }
        }
        if x0 == usize::MAX {
            if fragments.is_empty() {
                return None;
            }
            (x0, y0, x1, y1) = (0, 0, 0, 0);
        }
        let pixels = (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .map(|(x, y)| {
                gbuffer
                    .stored(x as u32, y as u32)
                    .filter(|(_, stored)| stored.object() == object)
            })
            .collect();
        Some(Sprite {
            x0: x0 as u32,
            y0: y0 as u32,
            width: (x1 - x0) as u32,
            height: (y1 - y0) as u32,
            pixels,
            fragments,
            buffer_width: gbuffer.width,
        })
    }

    /// Draws the sprite into `gbuffer` with the depth test.
    pub fn draw(&self, gbuffer: &mut GBuffer) {
        for (k, p) in self.pixels.iter().enumerate() {
            if let Some((depth, stored)) = p {
                let (x, y) = (
                    (k as u32 % self.width + self.x0) as i64,
                    (k as u32 / self.width + self.y0) as i64,
                );
                gbuffer.write_stored(x, y, *depth, stored);
            }
        }
        // (A buffer of another width would put them elsewhere.)
        if gbuffer.width == self.buffer_width {
            gbuffer.add_fragments(self.fragments.iter().copied());
        }
    }
}
