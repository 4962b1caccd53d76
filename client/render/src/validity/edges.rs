//! How much a texture's image changes where its surfaces part: the critical-point
//! error ([`super::critical`]) says how wide the widest gap a warp opens grows, not how
//! many edges open nor how much each shows. A sphere has no edge between surfaces; a
//! tree's leaves make one of every few texels, each between a leaf and what lies
//! behind it — another leaf in other light, or the sky.
//!
//! [`EdgeError`] is that count, weighted: for every pair of neighbouring texels of
//! different surfaces (both drawn, not joined — see [`Impostor`]), the squared step
//! between their colours, summed and divided by the texels drawn. A warp that moves
//! every edge by one texel changes about as many texels' worth of image as there are
//! such pairs, each by its step: the mean squared error it adds is about this figure
//! per texel of parallax. (A sphere scores 0; what the other objects here score is
//! beside the client's reference for it, `EDGE_ERROR_REFERENCE`.)
//!
//! ```
//! use glam::Vec3;
//! use relief_core::bounds::Aabb;
//! use relief_core::relief::{DepthBits, ReliefTexture, SourceCamera, SourceProjection};
//! use relief_render::impostor::Impostor;
//! use relief_render::validity::edges::EdgeError;
//! let bounds = Aabb::from_points([Vec3::splat(-1.0), Vec3::splat(1.0)]);
//! let eye = Vec3::new(0.0, 0.0, 5.0);
//! let camera = SourceCamera::facing(eye, &bounds, 4, 4, SourceProjection::Orthographic)?;
//! // (An empty texture has no edges.)
//! let impostor = Impostor::new(ReliefTexture::empty(camera, DepthBits::Eight, eye));
//! assert_eq!(EdgeError::of(&impostor).per_texel, 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::impostor::Impostor;

/// The mean squared colour step across a texture's edges between surfaces, per texel
/// drawn (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeError {
    /// Σ step² over the pairs of neighbouring texels of different surfaces, over the
    /// texels drawn; a step is the larger of the albedo's largest channel difference
    /// and the encoded normals' distance, as a fraction of full scale (one byte).
    pub per_texel: f32,
}

impl EdgeError {
    pub fn of(impostor: &Impostor) -> EdgeError {
        let texture = &impostor.texture;
        let (w, h) = (texture.camera.width as usize, texture.camera.height as usize);
        let empty = texture.depth_bits.empty();
        let drawn = |k: usize| texture.depth[k] != empty;
        let step = |k: usize, l: usize| {
            let channel = |a: [u8; 3], b: [u8; 3], c: usize| (a[c] as f32 - b[c] as f32) / 255.0;
            let (albedo, normal) = (
                (texture.albedo[k], texture.albedo[l]),
                (texture.normal[k], texture.normal[l]),
            );
            let albedo_step = (0..3)
                .map(|c| channel(albedo.0, albedo.1, c).abs())
                .fold(0.0, f32::max);
            let normal_step = (0..3)
                .map(|c| channel(normal.0, normal.1, c).powi(2))
                .sum::<f32>()
                .sqrt();
            albedo_step.max(normal_step)
        };
        let (mut sum, mut count) = (0.0f64, 0usize);
        for j in 0..h {
            for i in 0..w {
                let k = j * w + i;
                if !drawn(k) {
                    continue;
                }
                count += 1;
                if i + 1 < w && drawn(k + 1) && !impostor.right[k] {
                    sum += step(k, k + 1).powi(2) as f64;
                }
                if j + 1 < h && drawn(k + w) && !impostor.down[k] {
                    sum += step(k, k + w).powi(2) as f64;
                }
            }
        }
        EdgeError {
            per_texel: if count == 0 {
                0.0
            } else {
                (sum / count as f64) as f32
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{PLANE, square_over_plane};

    /// Against the definition counted by hand: a plane with a nearer square on it has
    /// its square's outline as edges, each pair stepping from one albedo to the other
    /// (a full step in one channel: 1 each); a plane of one surface has none; a
    /// square of the plane's own colour has edges of no step.
    #[test]
    fn edges_are_the_steps_between_surfaces() {
        let n = 16;
        let texture = |square| EdgeError::of(&Impostor::new(square_over_plane(n, 4..8, square))).per_texel;
        // A 4×4 square: 4 pairs across each of its four sides.
        let drawn = (n * n) as f32;
        assert_eq!(texture(([0, 255, 0], 40)), 16.0 / drawn);
        assert_eq!(texture(([0, 255, 0], PLANE.1)), 0.0);
        assert_eq!(texture((PLANE.0, 40)), 0.0);
    }
}
