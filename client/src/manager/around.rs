//! Eyes around an object: the angle between two, whether two are at a similar
//! distance. The geometry every decision of the manager is made in.

use glam::Vec3;

use super::policy::MAX_DISTANCE_RATIO;

/// The angle at `centre` between two eyes.
pub(super) fn angle_between(centre: Vec3, a: Vec3, b: Vec3) -> f32 {
    (a - centre).angle_between(b - centre)
}

/// Whether `a` is within [`MAX_DISTANCE_RATIO`] of `b`'s distance from `centre`.
pub(super) fn similar_distance(centre: Vec3, a: Vec3, b: Vec3) -> bool {
    let ratio = (a - centre).length() / (b - centre).length();
    (1.0 / MAX_DISTANCE_RATIO..=MAX_DISTANCE_RATIO).contains(&ratio)
}
