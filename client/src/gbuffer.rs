//! The G-buffer: what each pixel shows, before lighting.
//!
//! Geometry (the rasterizer) and impostors (the warps) write surfaces here with a depth
//! test, so they occlude each other correctly; [`GBuffer::shade`] then lights every
//! covered pixel once with [`relief_core::shading::Lighting::shade`] — the same model as
//! the ray-traced reference.

use glam::Vec3;
use rayon::prelude::*;

use relief_core::camera::Camera;
use relief_core::frame::{Frame, NO_OBJECT};
use relief_core::scene::Scene;
use relief_core::shading::to_rgb8;

/// One pixel's nearest surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GPixel {
    /// View-space depth (distance along the camera's forward axis); `f32::MAX` if empty
    /// (every value in the buffer is finite).
    pub depth: f32,
    /// Scene object index, or [`NO_OBJECT`].
    pub object: u32,
    /// Linear albedo, 8 bits per channel.
    pub albedo: [u8; 3],
    /// World-space unit normal.
    pub normal: Vec3,
}

impl GPixel {
    pub const EMPTY: GPixel = GPixel {
        depth: f32::MAX,
        object: NO_OBJECT,
        albedo: [0; 3],
        normal: Vec3::ZERO,
    };

    /// Replaces this pixel with `pixel` if that is nearer; returns whether it did.
    /// Non-finite or non-positive depths and non-finite normals are ignored, so no
    /// writer can poison the buffer with NaN.
    #[inline]
    pub fn keep_nearer(&mut self, pixel: GPixel) -> bool {
        if !(pixel.depth > 0.0 && pixel.depth.is_finite() && pixel.normal.is_finite()) {
            return false;
        }
        if pixel.depth < self.depth {
            *self = pixel;
            true
        } else {
            false
        }
    }

    /// True when a surface has been written.
    #[inline]
    pub fn is_covered(&self) -> bool {
        self.object != NO_OBJECT
    }
}

/// A `width × height` G-buffer, row-major, y down.
#[derive(Debug, Clone, PartialEq)]
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<GPixel>,
}

impl GBuffer {
    /// An empty buffer for `camera`'s resolution.
    pub fn new(width: u32, height: u32) -> Self {
        GBuffer {
            width,
            height,
            pixels: vec![GPixel::EMPTY; width as usize * height as usize],
        }
    }

    /// Empties every pixel, keeping the allocation.
    pub fn clear(&mut self) {
        self.pixels.fill(GPixel::EMPTY);
    }

    /// Writes `pixel` at `(x, y)` if it is nearer than what is there. Returns whether it
    /// was written. Out-of-range coordinates and non-finite or non-positive depths are
    /// ignored, so a caller can never write outside the buffer or poison it with NaN.
    #[inline]
    pub fn write(&mut self, x: i64, y: i64, pixel: GPixel) -> bool {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return false;
        }
        self.pixels[y as usize * self.width as usize + x as usize].keep_nearer(pixel)
    }

    /// The buffer's rows `y0..y1`, each with its row number, for writers that split
    /// the work by rows across threads ([`GPixel::keep_nearer`] on each pixel).
    pub fn par_rows(
        &mut self,
        y0: u32,
        y1: u32,
    ) -> impl IndexedParallelIterator<Item = (u32, &mut [GPixel])> {
        let w = self.width as usize;
        let (y0, y1) = (y0.min(self.height) as usize, y1.min(self.height) as usize);
        let rows = &mut self.pixels[y0 * w..y1.max(y0) * w];
        rows.par_chunks_mut(w.max(1))
            .enumerate()
            .map(move |(k, row)| ((y0 + k) as u32, row))
    }

    /// Lights every covered pixel with the scene's lighting and objects' specular
    /// terms; empty pixels get the background.
    pub fn shade(&self, scene: &Scene, camera: &Camera) -> Frame {
        let background = to_rgb8(scene.background);
        let w = self.width as usize;
        let mut frame = Frame::new(self.width, self.height, background);
        // Ray directions with a unit forward component: a pixel's position is
        // `eye + direction · depth`. They are linear in x, so step them along rows.
        let tan_half = camera.tan_half_fov();
        let aspect = self.width as f32 / self.height as f32;
        let x_step = camera.right * (2.0 / self.width as f32 * tan_half * aspect);
        frame
            .color
            .par_chunks_mut(w)
            .zip(frame.object.par_chunks_mut(w))
            .zip(self.pixels.par_chunks(w))
            .enumerate()
            .for_each(|(y, ((color, object), pixels))| {
                let sy = (1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32) * tan_half;
                let sx0 = (1.0 / self.width as f32 - 1.0) * tan_half * aspect;
                let row = camera.forward + camera.right * sx0 + camera.up * sy;
                for (x, p) in pixels.iter().enumerate() {
                    if !p.is_covered() {
                        continue;
                    }
                    let Some(o) = scene.objects.get(p.object as usize) else {
                        continue;
                    };
                    let position = camera.eye + (row + x_step * x as f32) * p.depth;
                    let albedo =
                        Vec3::new(p.albedo[0] as f32, p.albedo[1] as f32, p.albedo[2] as f32) * (1.0 / 255.0);
                    color[x] = to_rgb8(
                        scene
                            .lighting
                            .shade(albedo, p.normal, position, camera.eye, o.specular),
                    );
                    object[x] = p.object;
                }
            });
        frame
    }
}
