//! A relief texture prepared for display: the texture plus what every warp of it needs
//! and that does not depend on the eye — computed once when the texture arrives.

use glam::Vec3;

use relief_core::relief::{ReliefTexture, decode_normal_rgb8};

/// Which sides of an object's surfaces can show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Faces {
    /// Both: open surfaces (leaves, a plane) show their back from behind.
    #[default]
    Both,
    /// The front only: a closed surface ([`Mesh::is_closed`](relief_core::mesh::Mesh::is_closed))
    /// hides its back. The pre-warp leaves out texels turned away from the eye — seen
    /// by the texture's eye, hidden from this one — which would otherwise land past the
    /// silhouette as fringes.
    Front,
}

impl Faces {
    /// The faces of `object` that can show: the front only for a closed surface.
    pub fn of(object: &relief_core::scene::SceneObject) -> Faces {
        if object.is_closed() {
            Faces::Front
        } else {
            Faces::Both
        }
    }
}

/// A relief texture and its texel connectivity.
///
/// Two neighbouring texels belong to one surface when their depth difference is what
/// their normals' slope allows over one texel (with slack), so the warps interpolate
/// between them; otherwise there is a depth discontinuity (one surface in front of
/// another) and nothing is interpolated across it.
#[derive(Debug, Clone, PartialEq)]
pub struct Impostor {
    pub texture: ReliefTexture,
    /// Texel `k` is connected to its right neighbour.
    pub right: Vec<bool>,
    /// Texel `k` is connected to the neighbour below.
    pub down: Vec<bool>,
    /// Texel `k`'s albedo, encoded normal and depth level packed in one word: all the
    /// pre-warp reads of a texel, in one load (measured: 8 % of its time).
    pub packed: Vec<u64>,
    /// Which sides of the surfaces can show.
    pub faces: Faces,
}

/// Slack on the slope test: a surface may bend this much within one texel.
const SLOPE_SLACK: f32 = 2.0;
/// Slopes are capped (grazing normals say "any depth change"): steeper than this many
/// texels of depth per texel is treated as a discontinuity all the same.
const MAX_SLOPE: f32 = 24.0;

impl Impostor {
    pub fn new(texture: ReliefTexture) -> Impostor {
        let c = texture.camera;
        let (w, h) = (c.width as usize, c.height as usize);
        let empty = texture.depth_bits.empty();
        let quantum = c.depth_quantum(texture.depth_bits);
        let (a_len, b_len) = (c.a.length(), c.b.length());
        let (a_dir, b_dir) = (c.a / a_len, c.b / b_len);
        let depth = |k: usize| c.depth_of_level(texture.depth[k], texture.depth_bits);
        // Depth change per unit move along `axis` that a plane with normal `n` has.
        let slope = |n: Vec3, axis: Vec3| {
            let facing = n.dot(c.f).abs();
            if facing < 1e-6 {
                MAX_SLOPE
            } else {
                (n.dot(axis).abs() / facing).min(MAX_SLOPE)
            }
        };
        // How much wider than at the plane a texel is at displacement `t`
        // (`SourceCamera::texel_size_at` over its value at the plane, worked out once).
        let inverse_h = c.centre_distance().map_or(0.0, |h| 1.0 / h);
        let spread = |t: f32| 1.0 + t * inverse_h;
        // Each texel's depth and slopes worked out once (each is compared with up to
        // four neighbours): this runs for every texture level a client receives.
        // (Empty texels join nothing: nothing is worked out for them.)
        let mut depths = vec![0.0; w * h];
        let mut slopes_a = vec![0.0; w * h];
        let mut slopes_b = vec![0.0; w * h];
        for (k, (&level, &normal)) in texture.depth.iter().zip(&texture.normal).enumerate() {
            if level != empty {
                let n = decode_normal_rgb8(normal);
                depths[k] = depth(k);
                slopes_a[k] = slope(n, a_dir);
                slopes_b[k] = slope(n, b_dir);
            }
        }
        let joined = |k: usize, l: usize, slopes: &[f32], step: f32| {
            if texture.depth[k] == empty || texture.depth[l] == empty {
                return false;
            }
            let (dk, dl) = (depths[k], depths[l]);
            // (A perspective texture's neighbouring rays part with depth: the texel's
            // side where the surface lies.)
            let step = step * spread(dk.max(dl));
            let allowed = SLOPE_SLACK * step * slopes[k].max(slopes[l]) + step + 2.0 * quantum;
            (dk - dl).abs() <= allowed
        };
        let mut right = vec![false; w * h];
        let mut down = vec![false; w * h];
        for j in 0..h {
            for i in 0..w {
                let k = j * w + i;
                right[k] = i + 1 < w && joined(k, k + 1, &slopes_a, a_len);
                down[k] = j + 1 < h && joined(k, k + w, &slopes_b, b_len);
            }
        }
        let packed = (texture.albedo.iter().zip(&texture.normal).zip(&texture.depth))
            .map(|((&albedo, &normal), &level)| crate::warp::prewarp::pack_texel(albedo, normal, level))
            .collect();
        Impostor {
            texture,
            right,
            down,
            packed,
            faces: Faces::Both,
        }
    }

    /// The same impostor, showing `faces`.
    pub fn with_faces(self, faces: Faces) -> Impostor {
        Impostor { faces, ..self }
    }
}
