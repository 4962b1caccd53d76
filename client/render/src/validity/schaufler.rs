//! Schaufler's validity tests (thesis ch. 4.1.1, 5.2–5.3): when a sprite may be reused
//! as it is, when a texture is too coarse for the screen, and the resolution to ask
//! for.

use glam::Vec3;

use relief_core::bounds::Aabb;
use relief_core::camera::Camera;
use relief_core::relief::{SourceCamera, SourceProjection};

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

/// The sprite test: the image drawn through `old` may be shown unchanged through
/// `camera` while the object's extremes have moved by at most one pixel's angle
/// (β_transP ≤ β_screen). The sprite is those pixels copied, not a quad re-projected as
/// Schaufler's: the view's own turn moves them as much as the eye's step, so it counts
/// too (a camera turning on the spot slid the kept sphere 100 pixels off its place), and
/// another frame size or field of view ends it. Both cameras in the frame of `bounds`.
pub fn sprite_still_valid(bounds: &Aabb, old: &Camera, camera: &Camera) -> bool {
    let same_frame = (old.width, old.height, old.fov_y) == (camera.width, camera.height, camera.fov_y);
    let turn = old
        .forward
        .angle_between(camera.forward)
        .max(old.up.angle_between(camera.up));
    same_frame && parallax_angle(bounds, old.eye_f32(), camera.eye_f32()) + turn <= camera.pixel_angle()
}

/// β_impostor: the angle one texel subtends from `eye`, at the middle of the texture's
/// volume — where the object's surface lies on average (at the image plane, the
/// volume's nearest point, it asked for a third more texels per edge for an eye three
/// radii from a sphere, texels that the surface, mostly deeper, shows smaller).
pub fn texel_angle(texture: &SourceCamera, eye: Vec3) -> f32 {
    let middle = 0.5 * (texture.depth_near + texture.depth_far);
    let centre = volume_centre(texture);
    let distance = centre.distance(eye).max(f32::MIN_POSITIVE);
    2.0 * (0.5 * texture.texel_size_at(middle) / distance).atan()
}

/// The middle of the texture's volume: its image plane's centre, half-way down its
/// depth range.
pub fn volume_centre(texture: &SourceCamera) -> Vec3 {
    let (w, h) = (texture.width as f32, texture.height as f32);
    texture.point(0.5 * w, 0.5 * h, 0.5 * (texture.depth_near + texture.depth_far))
}

/// The resolution test (eq. 4-1): the texture is too coarse when a texel subtends more
/// than `k` pixels' angle (`k ≥ 1` tolerates slightly blurry impostors) where the
/// texture's volume shows ([`magnification`]). `camera` in the texture's frame.
pub fn needs_finer_texture(texture: &SourceCamera, camera: &Camera, k: f32) -> bool {
    magnification(texture, camera) > k
}

/// The pixels' angles one texel subtends where the texture's volume shows, as the
/// resolution test ([`needs_finer_texture`]) holds it: against the pixel there for a
/// solid ([`Camera::pixel_angle_towards`]: at the side of a wide view it needs finer
/// texels than at its centre), for leaves the centre's (see `pixel_angle` here). One
/// figure to test against several bounds. `camera` in the texture's frame.
pub fn magnification(texture: &SourceCamera, camera: &Camera) -> f32 {
    let held_to = pixel_angle(camera, texture.projection(), volume_centre(texture));
    texel_angle(texture, camera.eye_f32()) / held_to
}

/// The pixel angle a texture in `projection` is held to where `centre` shows: a
/// solid's, [`Camera::pixel_angle_towards`]; a sheet's (leaves: perspective textures),
/// the view's centre's, [`Camera::pixel_angle`]. Leaves are nearly all edge, moved by
/// up to half a texel wherever they show; held to the pixel at the side of a wide view,
/// the forest's trees there asked for textures past what is drawn as geometry, and its
/// 1280×720 frames took twice as long.
fn pixel_angle(camera: &Camera, projection: SourceProjection, centre: Vec3) -> f32 {
    match projection {
        SourceProjection::Orthographic => camera.pixel_angle_towards(centre),
        SourceProjection::Perspective => camera.pixel_angle(),
    }
}

/// The texture edge for the object with `bounds` seen from `eye` through `camera`: the
/// fewest texels whose texture facing `eye` in `projection` ([`SourceCamera::facing`],
/// the one a bake makes) passes the resolution test with `k` — eq. 5-1 with the texture's own span,
/// at the middle of its volume, so that no texel the screen cannot show is made (the
/// bounds' diagonal, as eq. 5-1 reads literally, asked for up to 1.7× the texels per
/// edge of a box seen face on). `None` when no texture faces the eye (inside the
/// bounds, or a non-finite eye or bounds).
pub fn resolution_for(
    bounds: &Aabb,
    eye: Vec3,
    projection: SourceProjection,
    camera: &Camera,
    k: f32,
) -> Option<u32> {
    let unit = SourceCamera::facing(eye, bounds, 1, 1, projection).ok()?;
    let span = unit.texel_size_at(0.5 * (unit.depth_near + unit.depth_far));
    let centre = volume_centre(&unit);
    let distance = centre.distance(eye);
    // texel_angle(N) = 2·atan(span / (2·N·distance)) ≤ k · pixel angle.
    let edge = 0.5 * span / (distance * (0.5 * k * pixel_angle(camera, projection, centre)).tan());
    Some(if edge.is_finite() {
        edge.ceil().clamp(1.0, u32::MAX as f32) as u32
    } else {
        u32::MAX
    })
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
        assert!(sprite_still_valid(&bounds, &camera, &camera));
        // A sideways step that moves the extremes by less than a pixel's angle …
        let step = 10.0 * camera.pixel_angle() * 0.5;
        let near = Camera {
            eye: (eye + Vec3::X * step).as_dvec3(),
            ..camera
        };
        assert!(sprite_still_valid(&bounds, &camera, &near));
        // … and one that moves them by several.
        let far = Camera {
            eye: (eye + Vec3::X * step * 8.0).as_dvec3(),
            ..camera
        };
        assert!(!sprite_still_valid(&bounds, &camera, &far));
        // The eye still, the view turned by a few pixels' angle: the object has moved
        // on screen.
        let turned = Camera::look_at(
            eye,
            Vec3::X * 10.0 * camera.pixel_angle() * 3.0,
            Vec3::Y,
            60.0,
            800,
            600,
        )
        .unwrap();
        assert!(!sprite_still_valid(&bounds, &camera, &turned));
        let wider = Camera {
            fov_y: camera.fov_y * 1.01,
            ..camera
        };
        assert!(!sprite_still_valid(&bounds, &camera, &wider));
    }

    #[test]
    fn resolution_is_the_fewest_texels_the_resolution_test_accepts() {
        let bounds = Aabb {
            min: Vec3::new(-1.0, 0.0, -0.5),
            max: Vec3::new(1.0, 3.0, 0.5),
        };
        for (eye, height) in [
            (Vec3::new(0.0, 1.0, 10.0), 1000),
            (Vec3::new(7.0, 6.0, -4.0), 360),
            (Vec3::new(300.0, 2.0, 1.0), 720),
            (Vec3::new(0.0, 1.5, 1.2), 300),
        ] {
            let camera =
                Camera::look_at(eye, bounds.center(), Vec3::Y, 60.0, height * 16 / 9, height).unwrap();
            for (k, projection) in [1.0, 2.0].into_iter().flat_map(|k| {
                [
                    (k, SourceProjection::Orthographic),
                    (k, SourceProjection::Perspective),
                ]
            }) {
                if SourceCamera::facing(eye, &bounds, 1, 1, projection).is_err() {
                    // (Too near for a perspective texture: none is asked for.)
                    assert_eq!(resolution_for(&bounds, eye, projection, &camera, k), None);
                    continue;
                }
                let n = resolution_for(&bounds, eye, projection, &camera, k).unwrap();
                let texture = |n| SourceCamera::facing(eye, &bounds, n, n, projection).unwrap();
                assert!(!needs_finer_texture(&texture(n), &camera, k), "{eye} {k}: {n}");
                assert!(
                    n == 1 || needs_finer_texture(&texture(n - 1), &camera, k),
                    "{eye} {k}: {n}"
                );
            }
        }
        // Seen from inside, no texture faces the eye.
        let inside = Camera::look_at(Vec3::new(0.0, 1.0, 0.0), Vec3::Z, Vec3::Y, 60.0, 64, 36).unwrap();
        for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
            assert_eq!(
                resolution_for(&bounds, inside.eye_f32(), projection, &inside, 1.0),
                None
            );
        }
    }
}
