//! Per-eye constants of the pre-warp and its lookup tables.
//!
//! With texel coordinates `(u, v)` (texel `i` has its centre at `u = i + 0.5`) and
//! displacement `d` along `f`, the pre-warp of eq. 3-1/3-2 moves a texel to the point
//! where the ray from the destination eye through its surface point crosses the source
//! plane:
//!
//! ```text
//! u' = (u + e1·k3·d) / (1 + k3·d),   v' = (v + e2·k3·d) / (1 + k3·d)
//! ```
//!
//! where `(e1, e2)` is the epipole (the eye projected on the plane) and `k3 = 1/(c·f)`,
//! `c·f` being the eye's distance in front of the plane. Each texel moves towards the
//! epipole by the factor `s = 1/(1 + k3·d) ∈ (0, 1]`. With depth stored as levels, a
//! table per level turns this into two additions and two multiplications per texel
//! (ch. 8.2): `u' = (u + add_u[q])·scale[q]`.

use glam::{Vec2, Vec3};

use relief_core::relief::ReliefTexture;

use super::WarpError;

/// The pre-warp of one texture for one eye.
#[derive(Debug, Clone, PartialEq)]
pub struct WarpParams {
    /// The eye.
    pub eye: Vec3,
    /// Distance of the eye in front of the texture plane, `c·f` (> 0).
    pub h: f32,
    /// `1 / h`.
    pub k3: f32,
    /// The epipole in texel coordinates.
    pub epipole: Vec2,
    /// Displacement of each depth level.
    pub depth: Vec<f32>,
    /// `e1·k3·d` per level.
    pub add_u: Vec<f32>,
    /// `e2·k3·d` per level.
    pub add_v: Vec<f32>,
    /// `1 / (1 + k3·d)` per level.
    pub scale: Vec<f32>,
}

impl WarpParams {
    /// The constants for showing `texture` from `eye`; an error when the eye is in or
    /// behind the texture plane (or anything is non-finite), where no warp exists.
    pub fn new(texture: &ReliefTexture, eye: Vec3) -> Result<Self, WarpError> {
        let c = &texture.camera;
        super::ensure_finite(c, eye)?;
        let to_eye = eye - c.origin;
        let h = -to_eye.dot(c.f);
        // Below this the table entries lose all precision (u' collapses onto the
        // epipole for every depth): treat as "in the plane".
        let h_min = (c.depth_far - c.depth_near).abs().max(c.a.length()) * 1e-5;
        if h <= h_min || !h.is_finite() {
            return Err(WarpError::EyeInPlane(h));
        }
        let k3 = 1.0 / h;
        let epipole = Vec2::new(
            to_eye.dot(c.a) / c.a.length_squared(),
            to_eye.dot(c.b) / c.b.length_squared(),
        );
        if !epipole.is_finite() {
            return Err(WarpError::NonFinite);
        }
        let levels = texture.depth_bits.max_level() as usize + 1;
        let depth: Vec<f32> = (0..levels)
            .map(|q| c.depth_of_level(q as u16, texture.depth_bits))
            .collect();
        let scale: Vec<f32> = depth.iter().map(|&d| 1.0 / (1.0 + k3 * d)).collect();
        let params = WarpParams {
            eye,
            h,
            k3,
            epipole,
            add_u: depth.iter().map(|&d| epipole.x * k3 * d).collect(),
            add_v: depth.iter().map(|&d| epipole.y * k3 * d).collect(),
            scale,
            depth,
        };
        // Finite tables keep every pre-warped position finite: the warps' loops over
        // the pixels between two positions rely on it.
        let tables = [&params.depth, &params.add_u, &params.add_v, &params.scale];
        if !tables.iter().all(|t| t.iter().all(|x| x.is_finite())) {
            return Err(WarpError::NonFinite);
        }
        Ok(params)
    }

    /// Pre-warped position of the texel centred at `(u, v)` with level `q`.
    #[inline]
    pub fn warp(&self, u: f32, v: f32, q: usize) -> Vec2 {
        Vec2::new(
            (u + self.add_u[q]) * self.scale[q],
            (v + self.add_v[q]) * self.scale[q],
        )
    }

    /// Pre-warped v of a row at `v` for a displacement `d` between levels (two-pass
    /// variants interpolate `d`).
    #[inline]
    pub fn warp_v(&self, v: f32, d: f32) -> f32 {
        (v + self.epipole.y * self.k3 * d) / (1.0 + self.k3 * d)
    }

    /// The largest displacement any level has.
    pub fn max_depth(&self) -> f32 {
        self.depth.last().copied().unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relief_core::bounds::Aabb;
    use relief_core::relief::{DepthBits, SourceCamera};

    fn texture() -> ReliefTexture {
        let bounds = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let eye = Vec3::new(0.5, 0.3, 5.0);
        ReliefTexture::empty(
            SourceCamera::facing(eye, &bounds, 64, 64).unwrap(),
            DepthBits::Eight,
            eye,
        )
    }

    /// The table form equals the definition: the eye-ray through the texel's surface
    /// point crosses the plane at the pre-warped position.
    #[test]
    fn table_matches_ray_plane_intersection() {
        let t = texture();
        let c = t.camera;
        let eye = Vec3::new(2.0, 1.5, 4.0);
        let p = WarpParams::new(&t, eye).unwrap();
        for (u, v, q) in [(3.5f32, 60.5f32, 0usize), (31.5, 7.5, 100), (63.5, 0.5, 254)] {
            let surface = c.origin + c.a * u + c.b * v + c.f * p.depth[q];
            let dir = surface - eye;
            let s = (c.origin - eye).dot(c.f) / dir.dot(c.f);
            let hit = eye + dir * s - c.origin;
            let want = Vec2::new(
                hit.dot(c.a) / c.a.length_squared(),
                hit.dot(c.b) / c.b.length_squared(),
            );
            assert!(
                p.warp(u, v, q).abs_diff_eq(want, 1e-3),
                "{:?} vs {want:?}",
                p.warp(u, v, q)
            );
            assert!((p.warp_v(v, p.depth[q]) - want.y).abs() < 1e-3);
        }
        // At the source eye the pre-warp keeps texels that lie in the plane in place.
        let same = WarpParams::new(&t, t.eye).unwrap();
        assert!(same.warp(10.5, 20.5, 0).abs_diff_eq(Vec2::new(10.5, 20.5), 1e-4));
    }

    #[test]
    fn eye_in_or_behind_the_plane_is_refused() {
        let t = texture();
        let c = t.camera;
        let in_plane = c.origin + c.a * 10.0 + c.b * 3.0;
        assert!(matches!(
            WarpParams::new(&t, in_plane),
            Err(WarpError::EyeInPlane(_))
        ));
        let behind = in_plane + c.f * 0.5;
        assert!(matches!(
            WarpParams::new(&t, behind),
            Err(WarpError::EyeInPlane(_))
        ));
        assert_eq!(WarpParams::new(&t, Vec3::NAN), Err(WarpError::NonFinite));
        // Finite inputs whose tables overflow (a depth range near f32::MAX): refused,
        // so pre-warped positions are always finite.
        let mut deep = texture();
        deep.camera.depth_far = f32::MAX;
        let eye = deep.camera.origin - deep.camera.f * 1e34 + deep.camera.a * 1e35;
        assert_eq!(WarpParams::new(&deep, eye), Err(WarpError::NonFinite));
        // Barely in front: finite tables, no NaN.
        let near = in_plane - c.f * 1e-3;
        let p = WarpParams::new(&t, near).unwrap();
        assert!(
            p.add_u
                .iter()
                .chain(&p.add_v)
                .chain(&p.scale)
                .all(|x| x.is_finite())
        );
    }
}
