//! Multi-resolution relief textures (thesis 4.1.1, eq. 4-1/5-1): never warp texels the
//! screen cannot show. A pyramid of 2×-downsampled copies; each frame warps the
//! coarsest level whose texel still subtends at most `k` pixels ([`MAX_TEXEL_PIXELS`]
//! wherever frames are drawn).

use relief_core::camera::Camera;
use relief_core::relief::{ReliefTexture, SourceCamera};

use crate::impostor::Impostor;
use crate::validity::schaufler::needs_finer_texture;

/// The angle a texel may span, in pixels' angles, before a finer pyramid level (or a
/// finer texture) is used: eq. 4-1's `k`. At 1, no texel is larger than a pixel, so
/// an impostor is as sharp as the frame can show.
pub const MAX_TEXEL_PIXELS: f32 = 1.0;

/// Pyramids stop at levels this many texels on the shorter side: a coarser level
/// would save a few hundred texels' warp and show blocks on screen.
pub const MIN_LEVEL_EDGE: u32 = 16;

/// The share of a coarse texel's area its finer texels must cover, and exceed, for it to
/// hold a surface ([`downsample`]): half, where a straight silhouette through the
/// texel's centre puts it. (Keeping exactly half, two of four texels at the first
/// level, grew silhouettes: the sample then lies on the silhouette and reaches past it.)
pub const HALF_COVERED: f32 = 0.5;

/// A relief texture and its downsampled copies, each prepared for display.
#[derive(Debug, Clone)]
pub struct Pyramid {
    /// Level 0 is the full texture; level `l` has `2^l`-times larger texels.
    pub levels: Vec<Impostor>,
}

impl Pyramid {
    /// Builds levels down to `min_size` texels on the shorter side.
    pub fn new(texture: ReliefTexture, min_size: u32) -> Pyramid {
        let empty = texture.depth_bits.empty();
        let mut coverage: Vec<f32> = texture.depth.iter().map(|&d| (d != empty) as u8 as f32).collect();
        let mut levels = vec![Impostor::new(texture)];
        while let Some(top) = levels.last() {
            let edges = (top.texture.camera.width, top.texture.camera.height);
            if edges.0.min(edges.1) / 2 < min_size.max(1) {
                break;
            }
            let (next, next_coverage) = downsample(top, &coverage);
            coverage = next_coverage;
            levels.push(Impostor::new(next));
        }
        Pyramid { levels }
    }

    /// The same pyramid, every level showing `faces` (see [`Impostor::with_faces`]).
    pub fn with_faces(self, faces: crate::impostor::Faces) -> Pyramid {
        Pyramid {
            levels: self
                .levels
                .into_iter()
                .map(|level| level.with_faces(faces))
                .collect(),
        }
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

/// Of a block's surface texels (index and depth), those on the front-most one's
/// surface: joined to it through the block (`joined`, the fine level's connectivity:
/// one surface however steep, as at a grazing rim, whose neighbours lie many texels
/// apart in depth), or within `same_surface` of its depth.
fn front_surface(
    surface: &[(usize, f32)],
    same_surface: f32,
    joined: impl Fn(usize, usize) -> bool,
) -> ([(usize, f32); 4], usize) {
    let front = surface.iter().map(|&(_, d)| d).fold(f32::INFINITY, f32::min);
    let mut reached = [false; 4];
    for (i, &(_, d)) in surface.iter().enumerate() {
        reached[i] = d <= front + same_surface;
    }
    // (Most blocks, inside a surface, are reached whole by the window alone.)
    loop {
        let before = reached;
        for (i, &(p, _)) in surface.iter().enumerate() {
            reached[i] |= surface.iter().zip(reached).any(|(&(q, _), r)| r && joined(p, q));
        }
        if reached == before {
            break;
        }
    }
    let mut kept = [(0, 0.0); 4];
    let mut n = 0;
    for (&texel, _) in surface.iter().zip(reached).filter(|&(_, r)| r) {
        kept[n] = texel;
        n += 1;
    }
    (kept, n)
}

/// The depth at a 2×2 block's centre from its texels `kept` (index and depth) on one
/// surface, `corner` giving each texel's place in the block: the mean of a diagonal's
/// two texels where one is kept whole (the plane through three texels, or the bilinear
/// surface through four, passes there), else `None`. (Three texels' mean lies a sixth
/// of the block's depth change off the centre: at a grazing rim, texels of depth far
/// from where they stand, which a turned eye sees displaced.)
fn centre_depth(kept: &[(usize, f32)], corner: impl Fn(usize) -> (usize, usize)) -> Option<f32> {
    let mut at = [[None; 2]; 2];
    for &(k, d) in kept {
        let (x, y) = corner(k);
        at[y][x] = Some(d);
    }
    let diagonal = |p: Option<f32>, q: Option<f32>| Some(0.5 * (p? + q?));
    match (diagonal(at[0][0], at[1][1]), diagonal(at[0][1], at[1][0])) {
        (Some(a), Some(b)) => Some(0.5 * (a + b)),
        (a, b) => a.or(b),
    }
}

/// Halves the resolution of `texture`, whose texels cover the fractions `coverage` of
/// their area (1 or 0 for a baked texture: a texel holds what its centre's ray hit, at
/// the outline a little further out: `relief_trace::rim`).
/// Returns the coarse texture and its texels' coverage, the mean of their blocks'.
///
/// A coarse texel holds a surface when its block's coverage exceeds [`HALF_COVERED`]:
/// so a silhouette stays where it was, as a texel's centre decides it. (Keeping every
/// block with any surface grew silhouettes outwards by a quarter of a coarse texel, more
/// at each level: a coarse level scored 3 dB worse than a texture baked at its size.)
/// It takes the average of the covered texels of its 2×2 block on the front-most one's
/// surface (`front_surface`: a silhouette keeps its front surface instead of blending
/// with what is behind), at the depth the block's centre has (`centre_depth`).
///
/// Judged by a grazing rim: a level of a fine texture's `fine.right`/`fine.down`
/// connectivity keeps the rim's steep texels, which a fixed depth window (two coarse
/// texels) cut off, leaving the rim nearer the eye than it is. Turned 12° from its
/// eye, the sphere's level 1 of a 360² texture then scored 1.4 dB above exact geometry
/// where it scored 0.1 below (a 184² texture baked at that size: 1.5 above), the knot's
/// 1.3 above where 0.2 below (1.0).
pub fn downsample(fine: &Impostor, coverage: &[f32]) -> (ReliefTexture, Vec<f32>) {
    let texture = &fine.texture;
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
    let same_surface = 2.0 * camera.a.length().max(camera.b.length());
    let mut out = ReliefTexture::empty(camera, bits, texture.eye);
    let mut out_coverage = vec![0.0; (w * h) as usize];
    // (Blocks are gathered into fixed arrays: this runs for every texture a client
    // receives, and a vector per block was half its cost.)
    for j in 0..h {
        for i in 0..w {
            // (A block cut by the texture's edge: its missing texels lie outside the
            // fine quad, where there is nothing.)
            let mut block = [0usize; 4];
            let mut in_texture = 0;
            for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (2 * i + di, 2 * j + dj);
                if x < c.width && y < c.height {
                    block[in_texture] = texture.index(x, y);
                    in_texture += 1;
                }
            }
            let block = &block[..in_texture];
            let target = out.index(i, j);
            let covered = block
                .iter()
                .map(|&k| coverage.get(k).copied().unwrap_or(0.0))
                .sum::<f32>()
                / 4.0;
            out_coverage[target] = covered;
            if covered <= HALF_COVERED {
                continue;
            }
            // The block's surface texels and their depths, then those on the front
            // surface.
            let mut surface = [(0usize, 0.0f32); 4];
            let mut n_surface = 0;
            for &k in block {
                if texture.depth[k] != empty {
                    surface[n_surface] = (k, c.depth_of_level(texture.depth[k], bits));
                    n_surface += 1;
                }
            }
            let corner_of = |k: usize| ((k % c.width as usize) & 1, (k / c.width as usize) & 1);
            let surface = &surface[..n_surface];
            if surface.is_empty() {
                continue;
            }
            let (kept, n_kept) = front_surface(surface, same_surface, |p, q| {
                let (p, q) = (p.min(q), p.max(q));
                (q == p + 1 && fine.right[p]) || (q == p + c.width as usize && fine.down[p])
            });
            let kept = &kept[..n_kept];
            let n = n_kept as f32;
            let mean = |f: &dyn Fn(usize, f32) -> f32| kept.iter().map(|&(k, d)| f(k, d)).sum::<f32>() / n;
            out.depth[target] = camera.level_of_depth(
                centre_depth(kept, corner_of).unwrap_or_else(|| mean(&|_, d| d)),
                bits,
            );
            for ch in 0..3 {
                out.albedo[target][ch] = (mean(&|k, _| texture.albedo[k][ch] as f32) + 0.5) as u8;
                out.normal[target][ch] = (mean(&|k, _| texture.normal[k][ch] as f32) + 0.5) as u8;
            }
        }
    }
    (out, out_coverage)
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use relief_core::bounds::Aabb;
    use relief_core::relief::DepthBits;

    use super::*;

    /// A `width × height` texture of the unit box seen from +z: texel `(i, j)` holds
    /// `surface(i, j)` — `None` for empty, else (depth, albedo, encoded normal).
    fn texture(
        width: u32,
        height: u32,
        surface: impl Fn(u32, u32) -> Option<(f32, [u8; 3], [u8; 3])>,
    ) -> ReliefTexture {
        let bounds = Aabb::from_points([Vec3::splat(-0.5), Vec3::splat(0.5)]);
        let eye = Vec3::new(0.0, 0.0, 4.0);
        let camera = SourceCamera::facing(
            eye,
            &bounds,
            width,
            height,
            relief_core::relief::SourceProjection::Orthographic,
        )
        .expect("faces the box");
        let bits = DepthBits::Sixteen;
        let mut t = ReliefTexture::empty(camera, bits, eye);
        for j in 0..height {
            for i in 0..width {
                if let Some((depth, albedo, normal)) = surface(i, j) {
                    let k = t.index(i, j);
                    t.depth[k] = camera.level_of_depth(depth, bits);
                    t.albedo[k] = albedo;
                    t.normal[k] = normal;
                }
            }
        }
        t
    }

    #[test]
    fn levels_halve_down_to_the_minimum_and_keep_the_quad() {
        let pyramid = Pyramid::new(texture(64, 48, |_, _| Some((0.5, [9; 3], [128; 3]))), 8);
        let sizes: Vec<(u32, u32)> = pyramid
            .levels
            .iter()
            .map(|l| (l.texture.camera.width, l.texture.camera.height))
            .collect();
        // 48 → 24 → 12; halving 12 would go below 8 texels.
        assert_eq!(sizes, [(64, 48), (32, 24), (16, 12)]);
        let quad = |c: &SourceCamera| (c.a * c.width as f32, c.b * c.height as f32, c.origin);
        let base = quad(&pyramid.levels[0].texture.camera);
        for level in &pyramid.levels {
            let (a, b, origin) = quad(&level.texture.camera);
            assert!(a.abs_diff_eq(base.0, 1e-5) && b.abs_diff_eq(base.1, 1e-5) && origin == base.2);
        }
    }

    #[test]
    fn downsampling_averages_the_front_surface_of_each_block() {
        // Rows alternate between a near surface and one 0.8 behind it; a few texels
        // are missing, and the last column's lower half. Odd size: the last blocks are
        // cut in half.
        let surface = |i: u32, j: u32| match (i, j) {
            (8, 4..) => None,
            _ if i % 3 == 2 && j > 4 => None,
            (_, j) if j % 2 == 0 => Some((0.1 + 0.01 * i as f32, [10 * i as u8, 0, 200], [128, 128, 255])),
            _ => Some((0.9, [255, 255, 0], [0, 128, 128])),
        };
        let fine = texture(9, 7, surface);
        let coverage: Vec<f32> = (0..7)
            .flat_map(|j| (0..9).map(move |i| surface(i, j).is_some() as u8 as f32))
            .collect();
        let (coarse, _) = downsample(&Impostor::new(fine), &coverage);
        let cc = coarse.camera;
        assert_eq!((cc.width, cc.height), (5, 4));
        // The two surfaces are 0.72 or more apart, far beyond two coarse texels (0.4):
        // a block's front group is its near row, never the far one.
        assert!(2.0 * cc.a.length().max(cc.b.length()) < 0.72);
        let empty = DepthBits::Sixteen.empty();
        for j in 0..4 {
            for i in 0..5 {
                // By construction: the block's covered texels on its even (near) row.
                let near: Vec<u32> = (2 * i..(2 * i + 2).min(9))
                    .filter(|&x| surface(x, 2 * j).is_some())
                    .collect();
                let k = coarse.index(i, j);
                let covered = (2 * j..2 * j + 2)
                    .flat_map(|y| (2 * i..2 * i + 2).map(move |x| (x, y)))
                    .filter(|&(x, y)| x < 9 && y < 7 && surface(x, y).is_some())
                    .count();
                if covered <= 2 {
                    assert_eq!(coarse.depth[k], empty, "({i}, {j}) covers {covered} of 4");
                    continue;
                }
                assert!(!near.is_empty(), "({i}, {j}): by construction");
                let n = near.len() as f32;
                let depth = near.iter().map(|&x| 0.1 + 0.01 * x as f32).sum::<f32>() / n;
                let got = cc.depth_of_level(coarse.depth[k], DepthBits::Sixteen);
                // (16-bit levels over the box's depth: a quantum is far below 1e-4.)
                assert!((got - depth).abs() < 1e-4, "({i}, {j}): {got} vs {depth}");
                let red = near.iter().map(|&x| (10 * x) as f32).sum::<f32>() / n;
                assert_eq!(coarse.albedo[k], [(red + 0.5) as u8, 0, 200], "({i}, {j})");
                assert_eq!(coarse.normal[k], [128, 128, 255], "({i}, {j})");
            }
        }
    }

    /// A steep ramp (a grazing rim: neighbours three coarse texels apart in depth,
    /// their normals saying so) keeps every texel of each block, at the depth of the
    /// block's centre; a fixed window of two coarse texels kept only the nearest.
    #[test]
    fn a_grazing_rim_keeps_its_depth_at_the_coarse_level() {
        use relief_core::relief::encode_normal_rgb8;
        let step = 1.0 / 32.0;
        let slope = 6.0;
        let depth = |i: u32| 0.1 + slope * step * (i as f32 + 0.5);
        // Rows 0-3 of columns 0-3 hold the ramp (its normal tilted by the slope along
        // the texture's `a`); the rest is empty.
        let fine = texture(32, 32, |i, j| {
            (i < 4 && j < 4).then(|| {
                (
                    depth(i),
                    [9; 3],
                    encode_normal_rgb8(Vec3::new(slope, 0.0, 1.0).normalize()),
                )
            })
        });
        let impostor = Impostor::new(fine);
        assert!(impostor.right[0] && impostor.right[2], "the ramp is one surface");
        let coverage: Vec<f32> = impostor
            .texture
            .depth
            .iter()
            .map(|&d| (d != DepthBits::Sixteen.empty()) as u8 as f32)
            .collect();
        let (coarse, _) = downsample(&impostor, &coverage);
        let cc = coarse.camera;
        assert!(
            slope * step > 2.0 * cc.a.length().max(cc.b.length()),
            "steeper than the window"
        );
        for i in 0..2 {
            let got = cc.depth_of_level(coarse.depth[coarse.index(i, 0)], DepthBits::Sixteen);
            let centre = 0.5 * (depth(2 * i) + depth(2 * i + 1));
            assert!(
                (got - centre).abs() < 1e-4,
                "coarse texel {i}: {got} against {centre}"
            );
        }
    }

    /// The front surface reaches every texel joined to it however the joins run, and
    /// the block's centre lies on the plane through three texels.
    #[test]
    fn a_block_keeps_what_is_joined_to_its_front_at_its_centre() {
        // Texels 0-3 of a 2×2 block (0, 1 above 2, 3), each a unit deeper than the window;
        // the front one is 2, joined to 3, 3 to 1, 1 to 0 (a chain round the block).
        let surface = [(0, 4.0), (1, 3.0), (2, 1.0), (3, 2.0)];
        let chain = [(2, 3), (3, 1), (1, 0)];
        let joined = |p: usize, q: usize| chain.iter().any(|&(a, b)| (a, b) == (p, q) || (b, a) == (p, q));
        let (kept, n) = front_surface(&surface, 0.5, joined);
        assert_eq!(n, 4, "{kept:?}");
        let (kept, n) = front_surface(&surface, 0.5, |p, q| (p, q) == (2, 3) || (p, q) == (3, 2));
        assert_eq!(&kept[..n], &[(2, 1.0), (3, 2.0)]);
        // Three texels of the plane d = 1 + 2x + 4y (texel centres at 0 and 1): the
        // centre's depth 1 + 1 + 2, where their mean is 3.
        let corner = |k: usize| (k % 2, k / 2);
        let three = [(0, 1.0), (1, 3.0), (2, 5.0)];
        assert_eq!(centre_depth(&three, corner), Some(4.0));
        assert_eq!(centre_depth(&[(0, 1.0), (1, 3.0)], corner), None);
    }

    #[test]
    fn coarse_levels_keep_a_silhouette_where_it_is() {
        // A disc of radius 20 texels in a 64² texture: every level, down to texels a
        // quarter of its radius, covers the disc's area (in level-0 texels) within
        // 5 %. (Keeping every block that holds any surface grew it by 7 % at level 1,
        // more at each level below.)
        let (centre, radius) = (31.3f32, 20.0f32);
        let inside = |i: u32, j: u32| {
            let (x, y) = (i as f32 + 0.5 - centre, j as f32 + 0.5 - centre);
            x * x + y * y <= radius * radius
        };
        let pyramid = Pyramid::new(
            texture(64, 64, |i, j| inside(i, j).then_some((0.5, [9; 3], [128; 3]))),
            16,
        );
        let area = std::f32::consts::PI * radius * radius;
        assert_eq!(pyramid.levels.len(), 3);
        for (l, level) in pyramid.levels.iter().enumerate() {
            let t = &level.texture;
            let texels = t.depth.iter().filter(|&&d| d != t.depth_bits.empty()).count();
            let covered = texels as f32 * 4f32.powi(l as i32);
            assert!(
                (covered / area - 1.0).abs() < 0.05,
                "level {l}: {covered} texels' area against the disc's {area}"
            );
        }
    }

    #[test]
    fn each_level_is_the_coarsest_the_resolution_test_accepts() {
        let pyramid = Pyramid::new(texture(256, 256, |_, _| Some((0.5, [9; 3], [128; 3]))), 4);
        let mut previous = 0;
        for distance in [2.0f32, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0] {
            let camera = Camera::look_at(Vec3::new(0.0, 0.0, distance), Vec3::ZERO, Vec3::Y, 40.0, 320, 240)
                .expect("camera");
            let level = pyramid.level_for(&camera, 1.0);
            let fine_enough =
                |l: usize| !needs_finer_texture(&pyramid.levels[l].texture.camera, &camera, 1.0);
            // Fine enough (or the finest), and the next coarser one is not.
            assert!(level == 0 || fine_enough(level), "{distance}: level {level}");
            assert!(
                level + 1 == pyramid.levels.len() || !fine_enough(level + 1),
                "{distance}: level {level}"
            );
            // Farther never needs finer texels.
            assert!(level >= previous, "{distance}: level {level} after {previous}");
            previous = level;
        }
        assert!(
            previous >= 3,
            "at 128 m the texture is far coarser: level {previous}"
        );
    }
}
