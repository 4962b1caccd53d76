//! Textures made by hand for the crate's unit tests.

use glam::Vec3;
use relief_core::bounds::Aabb;
use relief_core::relief::{DepthBits, ReliefTexture, SourceCamera, SourceProjection, encode_normal_rgb8};

/// The eye of [`square_over_plane`]'s texture.
pub(crate) const EYE: Vec3 = Vec3::new(0.0, 0.0, 10.0);

/// The plane of [`square_over_plane`]: its albedo and depth level.
pub(crate) const PLANE: ([u8; 3], u16) = ([255, 0, 0], 200);

/// A plane with a nearer square over it: an `n × n` orthographic 8-bit texture of the
/// box [−1, 1]³ seen from [`EYE`], every texel facing the eye, the plane's texels
/// [`PLANE`], those whose column and row both lie in `square` of albedo `albedo` at
/// depth level `level`.
pub(crate) fn square_over_plane(
    n: u32,
    square: std::ops::Range<u32>,
    (albedo, level): ([u8; 3], u16),
) -> ReliefTexture {
    let bounds = Aabb::from_points([Vec3::splat(-1.0), Vec3::splat(1.0)]);
    let camera = SourceCamera::facing(EYE, &bounds, n, n, SourceProjection::Orthographic).expect("camera");
    let mut texture = ReliefTexture::empty(camera, DepthBits::Eight, EYE);
    for j in 0..n {
        for i in 0..n {
            let k = texture.index(i, j);
            let inside = square.contains(&i) && square.contains(&j);
            (texture.albedo[k], texture.depth[k]) = if inside { (albedo, level) } else { PLANE };
            texture.normal[k] = encode_normal_rgb8(-camera.f);
        }
    }
    texture
}
