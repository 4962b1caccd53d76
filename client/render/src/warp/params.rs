//! Per-eye constants of the pre-warp and its lookup tables.
//!
//! With texel coordinates `(u, v)` (texel `i` has its centre at `u = i + 0.5`) and
//! displacement `d` along `f`, the pre-warp of eq. 3-1/3-2 moves a texel to the point
//! where the ray from the destination eye through its surface point crosses the source
//! plane. For an orthographic texture:
//!
//! ```text
//! u' = (u + e1·k3·d) / (1 + k3·d),   v' = (v + e2·k3·d) / (1 + k3·d)
//! ```
//!
//! where `(e1, e2)` is the eye's foot on the plane and `k3 = 1/h`, `h = c·f` being the
//! eye's distance in front of the plane. Each texel moves towards that point, the
//! epipole, by the factor `s = 1/(1 + k3·d) ∈ (0, 1]`.
//!
//! A perspective texture, seen from a centre at distance `h_s` in front of the plane
//! with its foot at `(c1, c2)`, keeps the form (with `g = d/h_s`, the surface point
//! `Q + (Q − C)·g`):
//!
//! ```text
//! u' = (u + add_u(d))·s(d),   s(d) = h·(1 + g) / (h + d),
//! add_u(d) = (d·e1 − g·h·c1) / (h·(1 + g))
//! ```
//!
//! (`g = 0` is the orthographic case). Every texel moves along the line through the
//! epipole `e* = (e − (h/h_s)·c) / (1 − h/h_s)`, where the line from the centre to the
//! eye crosses the plane: `u' = e* + (u − e*)·s(d)`. While the eye is nearer the plane
//! than the centre (`h < h_s`) the deeper texels move the more towards it (`s ≤ 1`),
//! as in the orthographic case; farther (`h > h_s`) they move away from it (`s ≥ 1`),
//! the deeper the more, and the visiting order turns round ([`WarpParams::outward`]).
//! With depth stored as levels, a table per level turns this into two additions and two
//! multiplications per texel (ch. 8.2): `u' = (u + add_u[q])·scale[q]`. Sixteen-bit
//! depth shares entries between neighbouring levels ([`WarpLevels`]).

use glam::{Vec2, Vec3};

use relief_core::relief::{DepthBits, ReliefTexture, SourceCamera};

use super::WarpError;

/// The depth levels the pre-warp's tables tell apart, in bits. Eight-bit depth is
/// warped level by level; 16-bit depth by its top 12 bits, so that each warp builds
/// tables of 4,096 entries rather than 65,535 (1 MB), at a displacement error of at
/// most 7.5 levels of 65,534: about 1/16 of what 8 bits leave.
pub const WARP_LEVEL_BITS: u32 = 12;

/// Which entry of the pre-warp's tables ([`WarpParams`]) a texture's depth level
/// uses: its top [`WARP_LEVEL_BITS`] bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WarpLevels {
    bits: DepthBits,
    shift: u32,
}

impl WarpLevels {
    pub fn new(bits: DepthBits) -> WarpLevels {
        WarpLevels {
            bits,
            shift: bits.bits().saturating_sub(WARP_LEVEL_BITS),
        }
    }

    /// The entry marking an empty texel; entries `0..empty` hold surfaces (for 8-bit
    /// depth, the levels themselves).
    pub fn empty(self) -> u16 {
        (self.bits.max_level() >> self.shift) + 1
    }

    /// The entry of depth level `q` ([`DepthBits::empty`] gives [`WarpLevels::empty`]).
    #[inline]
    pub fn entry(self, q: u16) -> u16 {
        if q == self.bits.empty() {
            self.empty()
        } else {
            q >> self.shift
        }
    }

    /// The displacement of each entry: the middle of its levels' (depth is linear in
    /// the level; for 8-bit depth, exactly the level's).
    fn depths(self, c: &SourceCamera) -> Vec<f32> {
        let last_level = self.bits.max_level();
        (0..self.empty())
            .map(|entry| {
                let first = entry << self.shift;
                let last = first.saturating_add((1 << self.shift) - 1).min(last_level);
                0.5 * (c.depth_of_level(first, self.bits) + c.depth_of_level(last, self.bits))
            })
            .collect()
    }
}

/// The pre-warp of one texture for one eye.
#[derive(Debug, Clone, PartialEq)]
pub struct WarpParams {
    /// The eye.
    pub eye: Vec3,
    /// Distance of the eye in front of the texture plane, `c·f` (> 0).
    pub h: f32,
    /// `1 / h`.
    pub k3: f32,
    /// The eye's foot on the plane (texel coordinates): where its ray along `f` crosses
    /// the plane.
    pub foot: Vec2,
    /// The point every texel moves towards or away from (texel coordinates); the
    /// eye's foot for an orthographic texture. Bounded (about a million texels away
    /// when the eye is as far from the plane as a perspective texture's centre).
    pub epipole: Vec2,
    /// Texels move away from the epipole (`s ≥ 1`): the eye is farther from the plane
    /// than a perspective texture's centre. The occlusion-compatible order is then from
    /// the epipole outwards.
    pub outward: bool,
    /// A perspective texture's `1/h_s` and its centre's foot; `(0, 0)` orthographic.
    source: (f32, Vec2),
    /// Which table entry each depth level uses.
    pub levels: WarpLevels,
    /// Displacement of each table entry (this and the three tables below are left
    /// empty by [`WarpParams::without_tables`]).
    pub depth: Vec<f32>,
    /// `add_u(d)` per entry.
    pub add_u: Vec<f32>,
    /// `add_v(d)` per entry.
    pub add_v: Vec<f32>,
    /// `s(d)` per entry.
    pub scale: Vec<f32>,
}

/// How near `h/h_s` may come to 1 (the eye as far from the plane as a perspective
/// texture's centre, the epipole at infinity) before the epipole is held at about a
/// million texels: far enough that ordering by it is ordering by direction, near
/// enough that `f32` keeps it finite.
const PARALLEL_EPIPOLE: f32 = 1e-6;

impl WarpParams {
    /// The constants for showing `texture` from `eye`; an error when the eye is in or
    /// behind the texture plane (or anything is non-finite), where no warp exists.
    pub fn new(texture: &ReliefTexture, eye: Vec3) -> Result<Self, WarpError> {
        let mut params = Self::without_tables(texture, eye)?;
        params.depth = params.levels.depths(&texture.camera);
        // (One straight loop per table, which the compiler vectorises: a 16-bit
        // texture's 4,096 entries are built for every warp.)
        params.add_u = params.depth.iter().map(|&d| params.at_depth(d).0.x).collect();
        params.add_v = params.depth.iter().map(|&d| params.at_depth(d).0.y).collect();
        params.scale = params.depth.iter().map(|&d| params.at_depth(d).1).collect();
        Ok(params)
    }

    /// The constants without the tables: for warping points at any displacement
    /// ([`WarpParams::warp_at`], [`WarpParams::warp_v`]), as the gap predictions do for
    /// every texture held at every eye weighed — where building a 16-bit texture's
    /// 4,096 entries each time cost the forest's frames 11–16 ms. [`WarpParams::warp`]
    /// and the pre-warp need [`WarpParams::new`]'s tables. Refused as `new` refuses.
    pub fn without_tables(texture: &ReliefTexture, eye: Vec3) -> Result<Self, WarpError> {
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
        let plane_coords = |p: Vec3| {
            Vec2::new(
                p.dot(c.a) / c.a.length_squared(),
                p.dot(c.b) / c.b.length_squared(),
            )
        };
        let foot = plane_coords(to_eye);
        let source = match (c.centre, c.centre_distance()) {
            (Some(centre), Some(h_s)) => (1.0 / h_s, plane_coords(centre - c.origin)),
            _ => (0.0, Vec2::ZERO),
        };
        let ratio = h * source.0;
        let outward = ratio > 1.0;
        let denominator = match 1.0 - ratio {
            x if x.abs() >= PARALLEL_EPIPOLE => x,
            x if x < 0.0 => -PARALLEL_EPIPOLE,
            _ => PARALLEL_EPIPOLE,
        };
        let epipole = (foot - source.1 * ratio) / denominator;
        if !epipole.is_finite() || !foot.is_finite() {
            return Err(WarpError::NonFinite);
        }
        let params = WarpParams {
            eye,
            h,
            k3: 1.0 / h,
            foot,
            epipole,
            outward,
            source,
            levels: WarpLevels::new(texture.depth_bits),
            depth: Vec::new(),
            add_u: Vec::new(),
            add_v: Vec::new(),
            scale: Vec::new(),
        };
        // Finite tables keep every pre-warped position finite: the warps' loops over
        // the pixels between two positions rely on it. `add(d)` and `s(d)` are each a
        // ratio of two linear functions of `d`: finite at both ends of the depth range,
        // with no pole between (a denominator keeping its sign), they are finite
        // throughout.
        let (near, far) = (c.depth_near, c.depth_far);
        let ends = [params.at_depth(near), params.at_depth(far)];
        let ends_finite = ends.iter().all(|(add, s)| add.is_finite() && s.is_finite());
        let one_sign = |a: f32, b: f32| a * b > 0.0;
        let inverse_h_s = params.source.0;
        let no_pole =
            one_sign(h + near, h + far) && one_sign(1.0 + near * inverse_h_s, 1.0 + far * inverse_h_s);
        if !(ends_finite && no_pole) {
            return Err(WarpError::NonFinite);
        }
        Ok(params)
    }

    /// `(add(d), s(d))` of the module docs for displacement `d`.
    #[inline]
    fn at_depth(&self, d: f32) -> (Vec2, f32) {
        let (inverse_h_s, centre_foot) = self.source;
        let g = d * inverse_h_s;
        let add = (self.foot * d - centre_foot * (g * self.h)) / (self.h * (1.0 + g));
        (add, self.h * (1.0 + g) / (self.h + d))
    }

    /// Pre-warped position of the texel centred at `(u, v)` whose depth level uses
    /// table entry `q` ([`WarpLevels::entry`]).
    #[inline]
    pub fn warp(&self, u: f32, v: f32, q: usize) -> Vec2 {
        Vec2::new(
            (u + self.add_u[q]) * self.scale[q],
            (v + self.add_v[q]) * self.scale[q],
        )
    }

    /// Pre-warped position of the point `uv` of the plane at displacement `d`, between
    /// levels (two-pass variants and predictions interpolate `d`).
    #[inline]
    pub fn warp_at(&self, uv: Vec2, d: f32) -> Vec2 {
        let (add, s) = self.at_depth(d);
        (uv + add) * s
    }

    /// Pre-warped v of a row at `v` for a displacement `d` between levels.
    #[inline]
    pub fn warp_v(&self, v: f32, d: f32) -> f32 {
        let (add, s) = self.at_depth(d);
        (v + add.y) * s
    }

    /// True for a perspective texture's warp.
    pub fn perspective(&self) -> bool {
        self.source.0 != 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relief_core::bounds::Aabb;
    use relief_core::relief::{DepthBits, SourceCamera, SourceProjection};

    fn texture(projection: SourceProjection) -> ReliefTexture {
        let bounds = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let eye = Vec3::new(0.5, 0.3, 5.0);
        ReliefTexture::empty(
            SourceCamera::facing(eye, &bounds, 64, 64, projection).unwrap(),
            DepthBits::Eight,
            eye,
        )
    }

    /// Every depth level's table entry holds a displacement within its bin: exactly
    /// its own with 8 bits (the table as before entries, bit for bit); with 16,
    /// within 7.5 levels. The empty level has the empty entry, which no surface level
    /// reaches.
    #[test]
    fn each_level_warps_at_its_entrys_displacement() {
        for bits in [DepthBits::Eight, DepthBits::Sixteen] {
            let mut t = texture(SourceProjection::Orthographic);
            t.depth_bits = bits;
            let c = &t.camera;
            let p = WarpParams::new(&t, t.eye).unwrap();
            let levels = p.levels;
            assert_eq!(levels.entry(bits.empty()), levels.empty());
            assert_eq!(p.depth.len(), levels.empty() as usize);
            assert_eq!(levels.empty(), if bits == DepthBits::Eight { 255 } else { 4096 });
            let per_level = (c.depth_far - c.depth_near) / bits.max_level() as f32;
            let allowed = match bits {
                DepthBits::Eight => 0.0,
                DepthBits::Sixteen => 7.5 * per_level,
            };
            for q in 0..=bits.max_level() {
                let entry = levels.entry(q);
                assert!(entry < levels.empty(), "level {q} reaches the empty entry");
                let off = (p.depth[entry as usize] - c.depth_of_level(q, bits)).abs();
                // (Slack for the rounding of the two depths averaged.)
                let slack = if bits == DepthBits::Eight {
                    0.0
                } else {
                    1e-6 * c.depth_far.abs()
                };
                assert!(off <= allowed + slack, "{bits:?} level {q}: {off} off");
            }
        }
    }

    /// The table form equals the definition: the eye-ray through the texel's surface
    /// point crosses the plane at the pre-warped position — for both projections, and
    /// for eyes nearer the plane than a perspective texture's centre, as far, and
    /// farther.
    #[test]
    fn table_matches_ray_plane_intersection() {
        for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
            let t = texture(projection);
            let c = t.camera;
            let away = t.eye - c.plane_centre();
            let eyes = [
                Vec3::new(2.0, 1.5, 4.0),
                t.eye + away * 0.3,
                t.eye - away * 0.2 + c.a * 9.0,
                t.eye + c.a * 30.0 - c.b * 4.0,
                t.eye + c.a * 1e-3,
            ];
            for eye in eyes {
                let p = WarpParams::new(&t, eye).unwrap();
                for (u, v, q) in [(3.5f32, 60.5f32, 0usize), (31.5, 7.5, 100), (63.5, 0.5, 254)] {
                    let surface = c.point(u, v, p.depth[q]);
                    let dir = surface - eye;
                    let s = (c.origin - eye).dot(c.f) / dir.dot(c.f);
                    let hit = eye + dir * s - c.origin;
                    let want = Vec2::new(
                        hit.dot(c.a) / c.a.length_squared(),
                        hit.dot(c.b) / c.b.length_squared(),
                    );
                    let got = p.warp(u, v, q);
                    assert!(
                        got.abs_diff_eq(want, 2e-3),
                        "{projection:?} {eye}: {got:?} vs {want:?}"
                    );
                    assert!(p.warp_at(Vec2::new(u, v), p.depth[q]).abs_diff_eq(want, 2e-3));
                    assert!((p.warp_v(v, p.depth[q]) - want.y).abs() < 2e-3);
                    // Along the line through the epipole, away from it when outward.
                    let (from, to) = (Vec2::new(u, v) - p.epipole, got - p.epipole);
                    assert!(from.perp_dot(to).abs() <= 1e-3 * from.length() * to.length().max(1.0));
                    if p.epipole.length() < 1e4 && q > 0 {
                        assert_eq!(to.length() > from.length(), p.outward, "{projection:?} {eye}");
                    }
                }
            }
            // At the source eye the pre-warp keeps texels that lie in the plane in place,
            // and a perspective texture's every texel.
            let same = WarpParams::new(&t, t.eye).unwrap();
            assert!(same.warp(10.5, 20.5, 0).abs_diff_eq(Vec2::new(10.5, 20.5), 1e-4));
            if projection == SourceProjection::Perspective {
                assert!(
                    same.warp(10.5, 20.5, 200)
                        .abs_diff_eq(Vec2::new(10.5, 20.5), 1e-3)
                );
            }
        }
    }

    #[test]
    fn eye_in_or_behind_the_plane_is_refused() {
        let t = texture(SourceProjection::Orthographic);
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
        let mut deep = texture(SourceProjection::Orthographic);
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
        // Without the tables: refused alike, and the same constants. A perspective
        // texture seen from beyond its centre's distance too.
        let mut perspective = texture(SourceProjection::Perspective);
        perspective.camera.depth_far *= 50.0;
        for (t, eye) in [
            (&t, in_plane),
            (&t, behind),
            (&t, Vec3::NAN),
            (&deep, eye),
            (&t, near),
            (&t, t.eye),
            (&perspective, perspective.eye * 3.0),
        ] {
            let (with, without) = (WarpParams::new(t, eye), WarpParams::without_tables(t, eye));
            match (with, without) {
                (Ok(with), Ok(without)) => {
                    assert_eq!(
                        (with.h, with.foot, with.epipole),
                        (without.h, without.foot, without.epipole)
                    );
                    assert!(without.depth.is_empty() && without.scale.is_empty());
                }
                (with, without) => assert_eq!(with.err(), without.err(), "{eye}"),
            }
        }
    }
}
