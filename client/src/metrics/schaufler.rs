//! Schaufler's validity tests (thesis ch. 4.1.1, 5.2–5.3): when a sprite may be reused
//! as it is, when a texture is too coarse for the screen, and the initial resolution.

use glam::Vec3;

use relief_core::bounds::Aabb;
use relief_core::camera::Camera;
use relief_core::relief::SourceCamera;

/// β_transP: the largest angle, over the corners of `bounds`, between the directions
/// to the corner from the old and from the new eye — how far the object's extremes
/// appear to move.
pub fn parallax_angle(bounds: &Aabb, old_eye: Vec3, new_eye: Vec3) -> f32 {
    bounds
        .corners()
        .iter()
        .map(|&p| {
            let (a, b) = (
                (p - old_eye).normalize_or_zero(),
                (p - new_eye).normalize_or_zero(),
            );
            a.angle_between(b)
        })
        .filter(|a| a.is_finite())
        .fold(0.0, f32::max)
}

/// The sprite test: the previous image may be shown unchanged while its extremes have
/// moved by at most one pixel's angle (β_transP ≤ β_screen).
pub fn sprite_still_valid(bounds: &Aabb, old_eye: Vec3, camera: &Camera) -> bool {
    parallax_angle(bounds, old_eye, camera.eye) <= camera.pixel_angle()
}

/// β_impostor: the angle one texel subtends from `eye`, at the texture's nearest
/// point (the centre of its image plane).
pub fn texel_angle(texture: &SourceCamera, eye: Vec3) -> f32 {
    let centre = texture.plane_centre();
    let distance = centre.distance(eye).max(f32::MIN_POSITIVE);
    2.0 * (0.5 * texture.a.length().max(texture.b.length()) / distance).atan()
}

/// The resolution test (eq. 4-1): the texture is too coarse when a texel subtends more
/// than `k` pixels' angle (`k ≥ 1` tolerates slightly blurry impostors).
pub fn needs_finer_texture(texture: &SourceCamera, camera: &Camera, k: f32) -> bool {
    texel_angle(texture, camera.eye) > k * camera.pixel_angle()
}

/// The initial resolution (eq. 5-1): texels enough for the object's projected size and
/// no more, `res_screen · size / (2 · distance · tan(fov/2))`, at least 1.
pub fn initial_resolution(screen_resolution: u32, object_size: f32, distance: f32, fov_y: f32) -> u32 {
    let r = screen_resolution as f32 * object_size / (2.0 * distance * (fov_y * 0.5).tan());
    if r.is_finite() {
        r.ceil().max(1.0) as u32
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sprite_test_follows_the_pixel_angle() {
        let bounds = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let eye = Vec3::new(0.0, 0.0, 10.0);
        let camera = Camera::look_at(eye, Vec3::ZERO, Vec3::Y, 60.0, 800, 600).unwrap();
        assert!(sprite_still_valid(&bounds, eye, &camera));
        // A sideways step that moves the extremes by less than a pixel's angle …
        let step = 10.0 * camera.pixel_angle() * 0.5;
        let near = Camera {
            eye: eye + Vec3::X * step,
            ..camera
        };
        assert!(sprite_still_valid(&bounds, eye, &near));
        // … and one that moves them by several.
        let far = Camera {
            eye: eye + Vec3::X * step * 8.0,
            ..camera
        };
        assert!(!sprite_still_valid(&bounds, eye, &far));
    }

    #[test]
    fn initial_resolution_matches_the_projected_size() {
        // A 2 m object 10 m away under a 90° field of view on 1000 rows covers 100 rows.
        assert_eq!(
            initial_resolution(1000, 2.0, 10.0, std::f32::consts::FRAC_PI_2),
            100
        );
        assert_eq!(initial_resolution(1000, 2.0, f32::INFINITY, 1.0), 1);
    }
}
