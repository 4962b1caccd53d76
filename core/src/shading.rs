//! The one lighting model of Relief: per-pixel Phong, two-sided, no shadows.
//!
//! The reference renderer and the client's display stage both call [`Lighting::shade`],
//! so image error measures the impostors, not a difference of lighting models. Colours
//! are linear RGB; [`to_rgb8`] clamps and quantises them for PNG output.

use glam::Vec3;

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
    /// Phong colour of a surface point:
    /// `albedo·ambient + Σ_l color_l · (albedo·max(n·l, 0) + k_s·max(r·v, 0)^s)`,
    /// with `r` the mirror of `l` about `n`. The normal is flipped to face the viewer,
    /// so thin surfaces (leaves) are lit on both sides.
    pub fn shade(&self, albedo: Vec3, normal: Vec3, position: Vec3, eye: Vec3, specular: Specular) -> Vec3 {
        let towards_eye = eye - position;
        let mut n = normal;
        if n.dot(towards_eye) < 0.0 {
            n = -n;
        }
        // Only the specular term needs the unit view direction (a square root and a
        // division per pixel, a fifth of the display's shading time without it).
        let view = if specular.strength > 0.0 {
            towards_eye.normalize_or_zero()
        } else {
            Vec3::ZERO
        };
        let mut color = albedo * self.ambient;
        for light in &self.lights {
            let (to_light, light_color) = match *light {
                Light::Directional { direction, color } => (-direction, color),
                Light::Point { position: p, color } => ((p - position).normalize_or_zero(), color),
            };
            let diffuse = n.dot(to_light);
            if diffuse <= 0.0 {
                continue;
            }
            let mut lit = albedo * diffuse;
            // No specular term for surfaces without one (and no `powf` for them).
            if specular.strength > 0.0 {
                let along = (2.0 * diffuse * n - to_light).dot(view);
                if along > 0.0 {
                    lit += Vec3::splat(along.powf(specular.shininess) * specular.strength);
                }
            }
            color += light_color * lit;
        }
        color
    }
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
        let c = lighting.shade(albedo, Vec3::Y, Vec3::ZERO, Vec3::Y * 3.0, s);
        assert!(c.abs_diff_eq(albedo * 1.1 + Vec3::splat(0.5), 1e-5), "{c}");
        // Seen from below, the normal flips to face the viewer; the light is then behind.
        let c = lighting.shade(albedo, Vec3::Y, Vec3::ZERO, -Vec3::Y * 3.0, s);
        assert!(c.abs_diff_eq(albedo * 0.1, 1e-5));
        assert_eq!(to_rgb8(Vec3::new(-1.0, 0.5, 2.0)), [0, 128, 255]);
    }
}
