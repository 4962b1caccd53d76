//! The ray/triangle test (Möller–Trumbore).

use glam::Vec3;

/// Intersects the ray `origin + t·direction` with the triangle `(v0, v0 + e1, v0 + e2)`.
/// Returns `(t, u, v)` for `t` in `[t_min, t_max)`; both faces count. Degenerate
/// triangles never hit.
#[inline(always)]
pub fn intersect_triangle(
    origin: Vec3,
    direction: Vec3,
    v0: Vec3,
    e1: Vec3,
    e2: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let p = direction.cross(e2);
    let det = e1.dot(p);
    let inv_det = 1.0 / det;
    // Zero or denormal determinants (degenerate or edge-on triangles) give inf/NaN here.
    if !inv_det.is_finite() {
        return None;
    }
    let s = origin - v0;
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = direction.dot(q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv_det;
    (t >= t_min && t < t_max).then_some((t, u, v))
}
