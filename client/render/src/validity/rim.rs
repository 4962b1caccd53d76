//! What a texture cannot show past its outline: the band of surface beyond its rim that
//! an eye turned from the texture's eye sees and the texture alone leaves empty.
//!
//! A texture's rays graze a closed surface at its outline (the rim); the surface goes
//! on beyond, out of their sight. An eye turned by `φ` towards a rim whose cross-section
//! has curvature radius `r` sees round it: its outline lies where the surface's normal
//! is turned a further `φ`, and it projects `r·(1 − cos φ)` outside where the texture's
//! rim lands. Only what a partner from the far side holds can fill that band; alone the
//! texture shows a ragged outline there (the fringes of a sphere drawn 21° from its
//! texture's eye: `r` is the sphere's radius, 60 pixels, and the band 4 pixels).
//!
//! `r` is measured on the texture: inwards of a rim texel (covered, with an empty
//! neighbour), against its outward normal, the covered texels one and two steps in give
//! `r = |p₁ − p₂| / ∠(n₁, n₂)` — exact on a sphere. (The rim texel's own depth lies
//! nearer the outline than its centre's: see `relief_trace::rim`.) Rims are grouped by the direction
//! their normal points in the texture's plane ([`RIM_SECTORS`]), each sector keeping its
//! median radius; an eye turned by `φ` in direction `d` turns a sector facing `o` by
//! `φ·max(0, o·d)`.

use glam::{Vec2, Vec3};

use relief_core::relief::{ReliefTexture, decode_normal_rgb8};

/// Directions of outward normals in the texture's plane the rim is grouped into: 16
/// sectors of 22.5°, over which a rim's bend (and `o·d`) changes little.
pub const RIM_SECTORS: usize = 16;

/// A rim texel whose normal lies less than this far out of the view direction (its
/// component in the plane, `|n − (n·f)f|`) is not where the surface bends away out of
/// sight but a sharp edge or a cut: no radius is measured there.
const GRAZING: f32 = 0.5;

/// Sectors with fewer rim texels than this keep no radius: a few texels of outline
/// are a corner, not a stretch of rim a band could show along.
const MIN_SECTOR_TEXELS: usize = 3;

/// The curvature radii of a texture's rim, by the direction its normals point.
#[derive(Debug, Clone, PartialEq)]
pub struct Rim {
    /// Median radius (world units) of the rim facing sector `s`
    /// (outward direction at angle `(s + ½)·2π/RIM_SECTORS` from `a`, towards `b`);
    /// 0 where the texture has no such rim.
    pub radius: [f32; RIM_SECTORS],
}

impl Rim {
    /// Measures the rim of `texture` (see the module docs). Radii are capped at half
    /// the diagonal of the texture's quad: a flat rim seen edge-on has no bend, and
    /// what lies beyond it is bounded by the object.
    pub fn find(texture: &ReliefTexture) -> Rim {
        let c = &texture.camera;
        let (w, h) = (c.width as i64, c.height as i64);
        let (a_dir, b_dir) = (c.a.normalize_or_zero(), c.b.normalize_or_zero());
        let cap = 0.5 * (c.a * c.width as f32 + c.b * c.height as f32).length();
        let covered = |i: i64, j: i64| {
            (0..w).contains(&i) && (0..h).contains(&j) && !texture.is_empty_texel(i as u32, j as u32)
        };
        let mut radii: Vec<Vec<f32>> = vec![Vec::new(); RIM_SECTORS];
        for j in 0..h {
            for i in 0..w {
                if !covered(i, j)
                    || [(1, 0), (-1, 0), (0, 1), (0, -1)]
                        .iter()
                        .all(|&(di, dj)| covered(i + di, j + dj))
                {
                    continue;
                }
                let k = texture.index(i as u32, j as u32);
                let normal = decode_normal_rgb8(texture.normal[k]);
                let outward = Vec2::new(normal.dot(a_dir), normal.dot(b_dir));
                if outward.length() < GRAZING {
                    continue;
                }
                let outward = outward.normalize();
                // The texels one and two steps inwards, if covered: their points and
                // normals. (Where only one is, as across a thin part, the rim texel
                // stands in for the first: its depth lies nearer the outline than its
                // centre's, so the radius comes out larger, and the band wider.)
                let step = (outward.x.round() as i64, outward.y.round() as i64);
                let at = |n: i64| {
                    let (ii, jj) = (i - n * step.0, j - n * step.1);
                    let inside = (0..w).contains(&ii) && (0..h).contains(&jj);
                    let point = inside
                        .then(|| texture.world_point(ii as u32, jj as u32))
                        .flatten()?;
                    Some((
                        point,
                        decode_normal_rgb8(texture.normal[texture.index(ii as u32, jj as u32)]),
                    ))
                };
                let ((p1, n1), (p2, n2)) = match (at(0), at(1), at(2)) {
                    (_, Some(first), Some(second)) => (first, second),
                    (Some(rim), Some(first), None) => (rim, first),
                    _ => continue,
                };
                let bend = n1.angle_between(n2);
                let radius = if bend > 0.0 {
                    (p1.distance(p2) / bend).min(cap)
                } else {
                    cap
                };
                radii[sector_of(outward)].push(radius);
            }
        }
        let mut radius = [0.0; RIM_SECTORS];
        for (r, mut found) in radius.iter_mut().zip(radii) {
            if found.len() >= MIN_SECTOR_TEXELS {
                let middle = found.len() / 2;
                *r = *found.select_nth_unstable_by(middle, f32::total_cmp).1;
            }
        }
        Rim { radius }
    }

    /// The widest band (world units, across the outline) that `texture`'s rim leaves
    /// unshown for an eye at `eye`, the texture made from `texture.eye`, both about
    /// `centre`.
    pub fn band(&self, texture: &ReliefTexture, centre: Vec3, eye: Vec3) -> f32 {
        let (from, to) = (
            (texture.eye - centre).normalize_or_zero(),
            (eye - centre).normalize_or_zero(),
        );
        let turn = from.angle_between(to);
        let across = to - from * from.dot(to);
        let c = &texture.camera;
        let d = Vec2::new(
            across.dot(c.a.normalize_or_zero()),
            across.dot(c.b.normalize_or_zero()),
        );
        if turn.is_nan() || turn <= 0.0 || d == Vec2::ZERO {
            return 0.0;
        }
        let d = d.normalize();
        (0..RIM_SECTORS)
            .map(|s| {
                let facing = sector_direction(s).dot(d).max(0.0);
                // (1 − cos x as 2·sin²(x/2): exact for the small turns that matter.)
                self.radius[s] * 2.0 * (0.5 * turn * facing).sin().powi(2)
            })
            .fold(0.0, f32::max)
    }
}

/// The sector of unit direction `o` in the texture's plane.
fn sector_of(o: Vec2) -> usize {
    let turns = o.y.atan2(o.x) / std::f32::consts::TAU;
    ((turns.rem_euclid(1.0) * RIM_SECTORS as f32) as usize).min(RIM_SECTORS - 1)
}

/// The middle direction of sector `s`.
fn sector_direction(s: usize) -> Vec2 {
    Vec2::from_angle((s as f32 + 0.5) * std::f32::consts::TAU / RIM_SECTORS as f32)
}

#[cfg(test)]
mod tests {
    use relief_core::bounds::Aabb;
    use relief_core::relief::{DepthBits, SourceCamera, SourceProjection, encode_normal_rgb8};

    use super::*;

    /// A `size²` orthographic texture of a sphere of radius `r` at the origin, seen from
    /// `eye`, worked out from the sphere's equation (no tracer).
    fn sphere(r: f32, eye: Vec3, size: u32) -> ReliefTexture {
        let bounds = Aabb::from_points([Vec3::splat(-r), Vec3::splat(r)]);
        let camera = SourceCamera::facing(eye, &bounds, size, size, SourceProjection::Orthographic)
            .expect("faces the sphere");
        let bits = DepthBits::Sixteen;
        let mut texture = ReliefTexture::empty(camera, bits, eye);
        for j in 0..size {
            for i in 0..size {
                // The ray q + f·t meets |p| = r where t² + 2(q·f)t + |q|² − r² = 0.
                let q = camera.texel_origin(i, j);
                let (half_b, c) = (q.dot(camera.f), q.length_squared() - r * r);
                let discriminant = half_b * half_b - c;
                if discriminant < 0.0 {
                    continue;
                }
                let t = -half_b - discriminant.sqrt();
                let k = texture.index(i, j);
                texture.depth[k] = camera.level_of_depth(t, bits);
                texture.normal[k] = encode_normal_rgb8((q + camera.f * t) / r);
            }
        }
        texture
    }

    /// A thin part, two texels across, keeps a radius at its rim: with only one texel
    /// inside each rim texel, the rim texel and that one measure it (a cylinder 0.9
    /// texels round, along `b`: measured 0.95 of its radius).
    #[test]
    fn a_thin_part_keeps_its_rims_radius() {
        let eye = Vec3::new(0.0, 0.0, 4.0);
        let size = 64;
        let bounds = Aabb::from_points([Vec3::new(-0.05, -1.0, -0.05), Vec3::new(0.05, 1.0, 0.05)]);
        let camera = SourceCamera::facing(eye, &bounds, size, size, SourceProjection::Orthographic)
            .expect("faces the cylinder");
        let r = 0.9 * camera.a.length();
        assert!(r < 0.05, "the cylinder lies within its bounds");
        let bits = DepthBits::Sixteen;
        let mut texture = ReliefTexture::empty(camera, bits, eye);
        // Across the cylinder's axis (y): the ray q + f·t meets |q⊥ + f⊥·t| = r.
        let across = |v: Vec3| v - Vec3::Y * v.y;
        for j in 0..size {
            for i in 0..size {
                let (q, f) = (across(camera.texel_origin(i, j)), across(camera.f));
                let (a, half_b, c) = (f.length_squared(), q.dot(f), q.length_squared() - r * r);
                let discriminant = half_b * half_b - a * c;
                if discriminant < 0.0 {
                    continue;
                }
                let t = (-half_b - discriminant.sqrt()) / a;
                let k = texture.index(i, j);
                texture.depth[k] = camera.level_of_depth(t, bits);
                texture.normal[k] = encode_normal_rgb8((q + f * t) / r);
            }
        }
        let rows_covered = (0..size)
            .filter(|&i| !texture.is_empty_texel(i, size / 2))
            .count();
        assert_eq!(rows_covered, 2, "two texels across");
        let rim = Rim::find(&texture);
        // The two sides face ±a, each on a boundary between two sectors (which one,
        // the normals' rounding decides).
        for outward in [Vec2::X, -Vec2::X] {
            let sectors = [0.01f32, -0.01].map(|turn| sector_of(outward.rotate(Vec2::from_angle(turn))));
            let measured = sectors.map(|s| rim.radius[s]).into_iter().fold(0.0, f32::max);
            assert!(
                measured > 0.5 * r && measured < 2.0 * r,
                "facing {outward}: radius {measured} for {r}: {rim:?}"
            );
        }
    }

    #[test]
    fn a_spheres_rim_has_its_radius_all_round() {
        let texture = sphere(0.5, Vec3::new(0.0, 0.0, 4.0), 128);
        let rim = Rim::find(&texture);
        for (s, r) in rim.radius.iter().enumerate() {
            assert!((r - 0.5).abs() < 0.02, "sector {s}: radius {r}, not 0.5: {rim:?}");
        }
    }

    /// The band is the sphere's `r·(1 − cos φ)` on the side the eye turned to (the
    /// sector's middle direction within 11.25° of the turn's: cos 11.25° of it), and
    /// nothing for no turn.
    #[test]
    fn the_band_grows_as_one_minus_the_cosine_of_the_turn() {
        let eye = Vec3::new(0.0, 0.0, 4.0);
        let texture = sphere(0.5, eye, 128);
        let rim = Rim::find(&texture);
        assert_eq!(rim.band(&texture, Vec3::ZERO, eye), 0.0);
        for degrees in [5.0f32, 10.0, 20.0, 40.0] {
            for axis in [Vec3::X, Vec3::Y] {
                let turned = glam::Quat::from_axis_angle(axis, degrees.to_radians()) * eye;
                let band = rim.band(&texture, Vec3::ZERO, turned);
                let exact = 0.5 * (1.0 - degrees.to_radians().cos());
                let nearest = 0.5 * (1.0 - (degrees.to_radians() * 11.25f32.to_radians().cos()).cos());
                assert!(
                    band > 0.95 * nearest && band < 1.05 * exact,
                    "{degrees}° about {axis}: band {band}, exact {exact}"
                );
            }
        }
    }
}
