//! The one lighting model of Relief: per-pixel Phong, two-sided, no shadows.
//!
//! The reference renderer and the client's display stage both call
//! [`Lighting::shade_lanes`] (one point: [`Lighting::shade`]), so image error measures
//! the impostors, not a difference of lighting models. Colours are linear RGB;
//! [`to_rgb8`] clamps and quantises them for PNG output.

use glam::Vec3;
use wide::{f32x8, i32x8, u32x8};

/// A light source. `color` already includes intensity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Light travelling along `direction` (unit), like the sun.
    Directional { direction: Vec3, color: Vec3 },
    /// Light from `position`, without fall-off (the scenes are small).
    Point { position: Vec3, color: Vec3 },
}

/// Specular part of a surface; the diffuse part is the albedo stored per texel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Specular {
    /// Specular reflectance `k_s` in `[0, 1]`.
    pub strength: f32,
    /// Phong exponent.
    pub shininess: f32,
}

impl Default for Specular {
    fn default() -> Self {
        Specular {
            strength: 0.2,
            shininess: 32.0,
        }
    }
}

/// Ambient term plus a list of lights.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Lighting {
    pub ambient: Vec3,
    pub lights: Vec<Light>,
}

impl Lighting {
    /// This lighting in a frame whose origin lies at `origin` of the world: point
    /// lights moved by it (in `f64`), so that points given relative to an eye far
    /// from the world's origin are lit as precisely as near it.
    pub fn relative_to(&self, origin: glam::DVec3) -> Lighting {
        let lights = self
            .lights
            .iter()
            .map(|light| match *light {
                Light::Point { position, color } => Light::Point {
                    position: (position.as_dvec3() - origin).as_vec3(),
                    color,
                },
                directional => directional,
            })
            .collect();
        Lighting {
            ambient: self.ambient,
            lights,
        }
    }
}

/// A surface point to light: everything [`Lighting::shade`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SurfacePoint {
    /// Diffuse colour, linear RGB.
    pub albedo: Vec3,
    /// Unit surface normal, either side.
    pub normal: Vec3,
    /// Position, in the frame the lighting is given in ([`Lighting::relative_to`]; point
    /// lights only read it).
    pub position: Vec3,
    /// From the point towards the eye, any length: the view ray's direction negated
    /// will do.
    pub towards_eye: Vec3,
    pub specular: Specular,
}

/// Points lit together: the model runs on this many lanes at once, one AVX register
/// wide (`wide` falls back to two SSE halves, or scalars, elsewhere).
pub const LANES: usize = 8;

/// Each lane's index: `l` in lane `l` (the offsets of [`LANES`] consecutive pixels).
pub const LANE_INDEX: f32x8 = f32x8::new([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);

/// The lanes whose bit is set in `bits` (bit `l`, lane `l`; `to_bitmask`'s), lowest
/// first.
#[inline(always)]
pub fn set_lanes(mut bits: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        let l = bits.trailing_zeros() as usize;
        bits &= bits.wrapping_sub(1);
        (l < LANES).then_some(l)
    })
}

/// All ones in the lanes whose bit is set in `bits` (bit `l`, lane `l`): a bit mask
/// (`to_bitmask`'s) back as a lane mask.
#[inline(always)]
pub fn lane_mask(bits: u32) -> u32x8 {
    let each = u32x8::from([1, 2, 4, 8, 16, 32, 64, 128]);
    (u32x8::splat(bits) & each).simd_eq(each)
}

/// [`LANES`] vectors, one SIMD register per component: lane `l` of `x`, `y`, `z` is
/// vector `l`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vec3x8 {
    pub x: f32x8,
    pub y: f32x8,
    pub z: f32x8,
}

impl Vec3x8 {
    /// `v` in every lane.
    #[inline(always)]
    pub fn splat(v: Vec3) -> Vec3x8 {
        Vec3x8 {
            x: f32x8::splat(v.x),
            y: f32x8::splat(v.y),
            z: f32x8::splat(v.z),
        }
    }

    /// The `l`-th vector in lane `l`; lanes past the vectors given are zero.
    #[inline(always)]
    pub fn gather(vectors: impl IntoIterator<Item = Vec3>) -> Vec3x8 {
        let mut v = [[0.0; LANES]; 3];
        for (l, f) in vectors.into_iter().take(LANES).enumerate() {
            (v[0][l], v[1][l], v[2][l]) = (f.x, f.y, f.z);
        }
        Vec3x8 {
            x: f32x8::new(v[0]),
            y: f32x8::new(v[1]),
            z: f32x8::new(v[2]),
        }
    }

    /// Lane `l` as a `Vec3`.
    #[inline(always)]
    pub fn lanes(self) -> [Vec3; LANES] {
        let (x, y, z) = (self.x.to_array(), self.y.to_array(), self.z.to_array());
        std::array::from_fn(|l| Vec3::new(x[l], y[l], z[l]))
    }

    #[inline(always)]
    pub fn dot(self, b: Vec3x8) -> f32x8 {
        self.x * b.x + self.y * b.y + self.z * b.z
    }

    /// Each lane scaled by its own factor.
    #[inline(always)]
    pub fn scale(self, s: f32x8) -> Vec3x8 {
        self.map(|c| c * s)
    }

    /// `f` of each component.
    #[inline(always)]
    pub fn map(self, f: impl Fn(f32x8) -> f32x8) -> Vec3x8 {
        Vec3x8 {
            x: f(self.x),
            y: f(self.y),
            z: f(self.z),
        }
    }

    /// `f` of each pair of components.
    #[inline(always)]
    pub fn zip(self, b: Vec3x8, f: impl Fn(f32x8, f32x8) -> f32x8) -> Vec3x8 {
        Vec3x8 {
            x: f(self.x, b.x),
            y: f(self.y, b.y),
            z: f(self.z, b.z),
        }
    }

    /// Unit length per lane, or zero where that is not defined (as
    /// `Vec3::normalize_or_zero`).
    #[inline(always)]
    pub fn normalize_or_zero(self) -> Vec3x8 {
        let reciprocal = f32x8::ONE / self.dot(self).sqrt();
        let defined = reciprocal.is_finite() & reciprocal.simd_gt(f32x8::ZERO);
        // (Selected after scaling: an infinite component times zero would be NaN.)
        self.map(|c| defined.select(c * reciprocal, f32x8::ZERO))
    }
}

/// [`LANES`] surface points to light, one per lane of each field: what
/// [`Lighting::shade_lanes`] reads. Lanes nobody uses may hold anything finite.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceLanes {
    pub albedo: Vec3x8,
    pub normal: Vec3x8,
    pub position: Vec3x8,
    pub towards_eye: Vec3x8,
    /// Specular strength and exponent of each lane's surface.
    pub strength: f32x8,
    pub shininess: f32x8,
}

impl SurfaceLanes {
    /// Up to [`LANES`] points, in order; the lanes past them are zero.
    pub fn gather(points: &[SurfacePoint]) -> SurfaceLanes {
        let mut strength = [0.0; LANES];
        let mut shininess = [0.0; LANES];
        for (l, p) in points.iter().take(LANES).enumerate() {
            (strength[l], shininess[l]) = (p.specular.strength, p.specular.shininess);
        }
        SurfaceLanes {
            albedo: Vec3x8::gather(points.iter().map(|p| p.albedo)),
            normal: Vec3x8::gather(points.iter().map(|p| p.normal)),
            position: Vec3x8::gather(points.iter().map(|p| p.position)),
            towards_eye: Vec3x8::gather(points.iter().map(|p| p.towards_eye)),
            strength: f32x8::new(strength),
            shininess: f32x8::new(shininess),
        }
    }
}

impl Lighting {
    /// Phong colour of a surface point:
    /// `albedo·ambient + Σ_l color_l · (albedo·max(n·l, 0) + k_s·max(r·v, 0)^s)`,
    /// with `r` the mirror of `l` about `n` and the specular term only where `n·l > 0`.
    /// The normal is flipped to face the viewer, so thin surfaces (leaves) are lit on
    /// both sides. One lane of [`Lighting::shade_lanes`], which defines the model.
    pub fn shade(&self, point: &SurfacePoint) -> Vec3 {
        self.shade_lanes(&SurfaceLanes::gather(std::slice::from_ref(point)))
            .lanes()[0]
    }

    /// Lights every point of `points` into the same place of `colors` (which must be
    /// as long), [`LANES`] at a time.
    pub fn shade_all(&self, points: &[SurfacePoint], colors: &mut [Vec3]) {
        assert_eq!(points.len(), colors.len(), "one colour per point");
        for (points, colors) in points.chunks(LANES).zip(colors.chunks_mut(LANES)) {
            let lit = self.shade_lanes(&SurfaceLanes::gather(points)).lanes();
            colors.copy_from_slice(&lit[..colors.len()]);
        }
    }

    /// The model (see [`Lighting::shade`]) on [`LANES`] points at once, without a
    /// branch per point: a frame lights a million pixels, and per point, with a
    /// branch per light, that took 5× as long.
    #[inline]
    pub fn shade_lanes(&self, s: &SurfaceLanes) -> Vec3x8 {
        let back = s.normal.dot(s.towards_eye).simd_lt(f32x8::ZERO);
        let n = s.normal.scale(back.select(-f32x8::ONE, f32x8::ONE));
        // Only the specular term needs the unit view direction.
        let has_specular = s.strength.simd_gt(f32x8::ZERO);
        let view = has_specular.any().then(|| s.towards_eye.normalize_or_zero());
        let mut color = s.albedo.zip(Vec3x8::splat(self.ambient), |a, b| a * b);
        for light in &self.lights {
            let (to_light, light_color) = match *light {
                Light::Directional { direction, color } => (Vec3x8::splat(-direction), color),
                Light::Point { position, color } => (
                    Vec3x8::splat(position)
                        .zip(s.position, |a, b| a - b)
                        .normalize_or_zero(),
                    color,
                ),
            };
            let cosine = n.dot(to_light);
            let lit = cosine.simd_gt(f32x8::ZERO);
            let diffuse = lit.select(cosine, f32x8::ZERO);
            let mut reflected = s.albedo.scale(diffuse);
            if let Some(view) = view {
                let along = n.scale(diffuse + diffuse).zip(to_light, |a, b| a - b).dot(view);
                let shows = has_specular & lit & along.simd_gt(f32x8::ZERO);
                if shows.any() {
                    // (Elsewhere `along` may be ≤ 0: keep `powf` away from it.)
                    let base = shows.select(along, f32x8::ONE);
                    let highlight = shows.select(power(base, s.shininess) * s.strength, f32x8::ZERO);
                    reflected = reflected.map(|r| r + highlight);
                }
            }
            let c = Vec3x8::splat(light_color);
            color = color.zip(c.zip(reflected, |a, b| a * b), |a, b| a + b);
        }
        color
    }
}

/// `base^exponent` per lane, `base > 0`. An exponent that is the same small whole
/// number in every lane (a group of pixels of one object, the usual case) takes square
/// and multiply — a few multiplies where `powf` evaluates a logarithm and an exponential
/// (a fifth of a frame's shading); any other falls back to `powf`. Each squaring
/// doubles the rounding error: the two agree within about `k·2⁻²⁴` relative (4e-5 at
/// 1024), far below an 8-bit colour step.
#[inline]
fn power(base: f32x8, exponent: f32x8) -> f32x8 {
    let k = exponent.to_array()[0];
    let whole = (1.0..=MAX_WHOLE_EXPONENT).contains(&k) && k.fract() == 0.0;
    if !whole || !exponent.simd_eq(f32x8::splat(k)).all() {
        return base.powf_simd(exponent);
    }
    let mut k = k as u32;
    let (mut result, mut square) = (f32x8::ONE, base);
    loop {
        if k & 1 == 1 {
            result *= square;
        }
        k >>= 1;
        if k == 0 {
            return result;
        }
        square *= square;
    }
}

/// The largest exponent [`power`] multiplies out (10 squarings at most).
const MAX_WHOLE_EXPONENT: f32 = 1024.0;

/// [`to_rgb8`] of each lane.
#[inline(always)]
pub fn to_rgb8_lanes(color: Vec3x8) -> [[u8; 3]; LANES] {
    let byte =
        |c: f32x8| (c.max(f32x8::ZERO).min(f32x8::ONE) * f32x8::splat(255.0) + f32x8::splat(0.5)).trunc_int();
    // (Packed as one word per pixel first: gathering three separate byte arrays
    // compiled to ~90 instructions per eight pixels.)
    let packed: i32x8 = byte(color.x) | (byte(color.y) << 8) | (byte(color.z) << 16);
    packed.to_array().map(|p| {
        let [r, g, b, _] = (p as u32).to_le_bytes();
        [r, g, b]
    })
}

/// Clamps a linear colour to `[0, 1]` and rounds it to 8 bits per channel.
#[inline]
pub fn to_rgb8(color: Vec3) -> [u8; 3] {
    let c = (color.clamp(Vec3::ZERO, Vec3::ONE) * 255.0 + Vec3::splat(0.5)).to_array();
    [c[0] as u8, c[1] as u8, c[2] as u8]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phong_terms() {
        let lighting = Lighting {
            ambient: Vec3::splat(0.1),
            lights: vec![Light::Directional {
                direction: -Vec3::Y,
                color: Vec3::ONE,
            }],
        };
        let s = Specular {
            strength: 0.5,
            shininess: 8.0,
        };
        let albedo = Vec3::new(0.5, 0.25, 1.0);
        // Light, normal and view aligned: ambient + full diffuse + full specular.
        let point = |towards_eye| SurfacePoint {
            albedo,
            normal: Vec3::Y,
            position: Vec3::ZERO,
            towards_eye,
            specular: s,
        };
        let c = lighting.shade(&point(Vec3::Y * 3.0));
        assert!(c.abs_diff_eq(albedo * 1.1 + Vec3::splat(0.5), 1e-5), "{c}");
        // Seen from below, the normal flips to face the viewer; the light is then behind.
        let c = lighting.shade(&point(-Vec3::Y * 3.0));
        assert!(c.abs_diff_eq(albedo * 0.1, 1e-5));
        assert_eq!(to_rgb8(Vec3::new(-1.0, 0.5, 2.0)), [0, 128, 255]);
    }

    /// The model written per point with a branch per light and the standard `powf`,
    /// as it first was: the lanes must give its values (within the vectorised
    /// `powf`'s rounding), for every mix of lights, sides and specular terms.
    fn one_point(lighting: &Lighting, p: &SurfacePoint) -> Vec3 {
        let mut n = p.normal;
        if n.dot(p.towards_eye) < 0.0 {
            n = -n;
        }
        let view = p.towards_eye.normalize_or_zero();
        let mut color = p.albedo * lighting.ambient;
        for light in &lighting.lights {
            let (to_light, light_color) = match *light {
                Light::Directional { direction, color } => (-direction, color),
                Light::Point { position, color } => ((position - p.position).normalize_or_zero(), color),
            };
            let diffuse = n.dot(to_light);
            if diffuse <= 0.0 {
                continue;
            }
            let mut lit = p.albedo * diffuse;
            if p.specular.strength > 0.0 {
                let along = (2.0 * diffuse * n - to_light).dot(view);
                if along > 0.0 {
                    lit += Vec3::splat(along.powf(p.specular.shininess) * p.specular.strength);
                }
            }
            color += light_color * lit;
        }
        color
    }

    /// Whole exponents shared by all lanes are multiplied out; the result is `powf`'s
    /// within `k·2⁻²⁴` relative, and mixed or fractional exponents take `powf`.
    #[test]
    fn power_matches_powf() {
        let bases: [f32; LANES] = [1e-3, 0.1, 0.5, 0.9, 0.99, 0.999_9, 1.0, 0.75];
        let mixed = f32x8::new([1.0, 2.0, 3.0, 7.5, 16.0, 48.0, 64.0, 1024.0]);
        for exponent in [1.0, 2.0, 5.0, 16.0, 48.0, 64.0, 1000.0, 1024.0, 1025.0, 2.5] {
            for (exponents, e) in [
                (f32x8::splat(exponent), [exponent; LANES]),
                (mixed, mixed.to_array()),
            ] {
                let got = power(f32x8::new(bases), exponents).to_array();
                for l in 0..LANES {
                    let want = bases[l].powf(e[l]);
                    assert!(
                        (got[l] - want).abs() <= e[l].max(1.0) * 6e-8 * want + 1e-30,
                        "{}^{}: {} vs {want}",
                        bases[l],
                        e[l],
                        got[l]
                    );
                }
            }
        }
    }

    #[test]
    fn lanes_match_the_model_point_by_point() {
        let mut seed = 0x9e37_79b9_u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        let mut vector = || Vec3::new(next(), next(), next());
        let lighting = Lighting {
            ambient: Vec3::new(0.1, 0.2, 0.15),
            lights: vec![
                Light::Directional {
                    direction: vector().normalize(),
                    color: Vec3::new(0.9, 0.8, 0.7),
                },
                Light::Point {
                    position: vector() * 5.0,
                    color: Vec3::new(0.3, 0.4, 0.5),
                },
                Light::Directional {
                    direction: vector().normalize(),
                    color: Vec3::splat(0.25),
                },
            ],
        };
        let points: Vec<SurfacePoint> = (0..1000)
            .map(|k| SurfacePoint {
                albedo: vector().abs(),
                normal: vector().normalize(),
                position: vector() * 3.0,
                // Some eyes on the surface itself: no view direction.
                towards_eye: if k % 97 == 0 { Vec3::ZERO } else { vector() * 4.0 },
                specular: Specular {
                    strength: if k % 3 == 0 { 0.0 } else { vector().x.abs() },
                    shininess: 1.0 + 63.0 * vector().x.abs(),
                },
            })
            .collect();
        let mut colors = vec![Vec3::ZERO; points.len()];
        lighting.shade_all(&points, &mut colors);
        let mut highlights = 0;
        for (p, &c) in points.iter().zip(&colors) {
            let expected = one_point(&lighting, p);
            assert!(
                c.abs_diff_eq(expected, 1e-5 * expected.max_element().max(1.0)),
                "{c} vs {expected}: {p:?}"
            );
            assert_eq!(lighting.shade(p), c);
            highlights += (p.specular.strength > 0.0 && c.max_element() > 0.5) as usize;
        }
        assert!(highlights > 50, "{highlights} highlights");
    }

    #[test]
    fn lanes_quantise_like_to_rgb8() {
        let values: Vec<Vec3> = (0..64)
            .map(|k| {
                let t = k as f32 / 63.0;
                Vec3::new(t * 1.2 - 0.1, (t * 255.0).fract(), 0.5 / 255.0 * k as f32)
            })
            .chain([Vec3::new(f32::NAN, f32::INFINITY, f32::NEG_INFINITY)])
            .collect();
        for chunk in values.chunks(LANES) {
            let bytes = to_rgb8_lanes(Vec3x8::gather(chunk.iter().copied()));
            for (v, b) in chunk.iter().zip(bytes) {
                assert_eq!(b, to_rgb8(*v), "{v}");
            }
        }
    }
}
