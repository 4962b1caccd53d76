//! Multi-resolution relief textures (thesis 4.1.1, eq. 4-1/5-1): never warp texels the
//! screen cannot show. A pyramid of 2×-downsampled copies; each frame warps the
//! coarsest level whose texel still subtends at most `k` pixels.

use relief_core::camera::Camera;
use relief_core::relief::{ReliefTexture, SourceCamera};

use crate::impostor::Impostor;
use crate::metrics::schaufler::needs_finer_texture;

/// A relief texture and its downsampled copies, each prepared for display.
#[derive(Debug, Clone)]
pub struct Pyramid {
    /// Level 0 is the full texture; level `l` has `2^l`-times larger texels.
    pub levels: Vec<Impostor>,
}

impl Pyramid {
    /// Builds levels down to `min_size` texels on the shorter side.
    pub fn new(texture: ReliefTexture, min_size: u32) -> Pyramid {
        let mut levels = vec![Impostor::new(texture)];
        loop {
            let top = &levels[levels.len() - 1].texture;
            if top.camera.width.min(top.camera.height) / 2 < min_size.max(1) {
                break;
            }
            let next = downsample(top);
            levels.push(Impostor::new(next));
        }
        Pyramid { levels }
    }

    /// The coarsest level fine enough for `camera` (texel angle ≤ `k` pixel angles),
    /// or the finest when none is.
    pub fn level_for(&self, camera: &Camera, k: f32) -> usize {
        (0..self.levels.len())
            .rev()
            .find(|&l| !needs_finer_texture(&self.levels[l].texture.camera, camera, k))
            .unwrap_or(0)
    }
}

/// Halves the resolution: each texel takes the average of the covered texels of its
/// 2×2 block that lie within two of the block's texel sizes of the front-most one (so
/// a silhouette keeps its front surface instead of blending with what is behind).
pub fn downsample(texture: &ReliefTexture) -> ReliefTexture {
    let c = texture.camera;
    let (w, h) = (c.width.div_ceil(2), c.height.div_ceil(2));
    let camera = SourceCamera {
        width: w,
        height: h,
        a: c.a * (c.width as f32 / w as f32),
        b: c.b * (c.height as f32 / h as f32),
        ..c
    };
    let bits = texture.depth_bits;
    let empty = bits.empty();
    let tolerance = 2.0 * camera.a.length().max(camera.b.length());
    let mut out = ReliefTexture::empty(camera, bits, texture.eye);
    for j in 0..h {
        for i in 0..w {
            let block: Vec<usize> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .into_iter()
                .map(|(di, dj)| (2 * i + di, 2 * j + dj))
                .filter(|&(x, y)| x < c.width && y < c.height)
                .map(|(x, y)| texture.index(x, y))
                .filter(|&k| texture.depth[k] != empty)
                .collect();
            let Some(front) = block
                .iter()
                .map(|&k| c.depth_of_level(texture.depth[k], bits))
                .reduce(f32::min)
            else {
                continue;
            };
            let kept: Vec<usize> = block
                .into_iter()
                .filter(|&k| c.depth_of_level(texture.depth[k], bits) <= front + tolerance)
                .collect();
            let n = kept.len() as f32;
            let mean = |f: &dyn Fn(usize) -> f32| kept.iter().map(|&k| f(k)).sum::<f32>() / n;
            let target = out.index(i, j);
            out.depth[target] =
                camera.level_of_depth(mean(&|k| c.depth_of_level(texture.depth[k], bits)), bits);
            for ch in 0..3 {
                out.albedo[target][ch] = (mean(&|k| texture.albedo[k][ch] as f32) + 0.5) as u8;
                out.normal[target][ch] = (mean(&|k| texture.normal[k][ch] as f32) + 0.5) as u8;
            }
        }
    }
    out
}
