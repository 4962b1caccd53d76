//! An independent ray caster for checking the tracer: every triangle of a mesh, in
//! `f64`, by signed volumes (the Plücker form of the ray–triangle test) rather than the
//! tracer's Möller–Trumbore in `f32`. It shares no code with `relief_trace`, so a
//! mistake there cannot be repeated here.

use glam::Vec3;

use relief_core::mesh::Mesh;

/// The nearest hit of a ray, as the oracle finds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OracleHit {
    pub t: f64,
    pub triangle: usize,
    /// Barycentric weights of corners 1 and 2.
    pub u: f64,
    pub v: f64,
}

/// Where the ray `origin + t·direction` (`t > 0`) crosses triangle `corners`, if it
/// does: `(t, u, v)`. A ray through an edge or a corner hits (edges are shared, and
/// either neighbour may answer for them). Edge-on and degenerate triangles are missed.
pub fn ray_triangle(origin: Vec3, direction: Vec3, corners: [Vec3; 3]) -> Option<(f64, f64, f64)> {
    let (o, d) = (origin.as_dvec3(), direction.as_dvec3());
    let [a, b, c] = corners.map(|p| p.as_dvec3() - o);
    // The signed volume each edge makes with the ray: all of one sign when the ray
    // passes inside; each, over their sum, is the weight of the opposite corner.
    let (wa, wb, wc) = (d.dot(b.cross(c)), d.dot(c.cross(a)), d.dot(a.cross(b)));
    let inside = (wa >= 0.0 && wb >= 0.0 && wc >= 0.0) || (wa <= 0.0 && wb <= 0.0 && wc <= 0.0);
    let sum = wa + wb + wc;
    if !inside || sum == 0.0 {
        return None;
    }
    let (u, v) = (wb / sum, wc / sum);
    let point = a * (wa / sum) + b * u + c * v;
    let t = point.dot(d) / d.length_squared();
    (t > 0.0).then_some((t, u, v))
}

/// The nearest triangle of `mesh` the ray crosses.
pub fn nearest_hit(mesh: &Mesh, origin: Vec3, direction: Vec3) -> Option<OracleHit> {
    (0..mesh.triangle_count())
        .filter_map(|k| {
            let (t, u, v) = ray_triangle(origin, direction, mesh.corners(k))?;
            Some(OracleHit { t, triangle: k, u, v })
        })
        .min_by(|a, b| a.t.total_cmp(&b.t))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against values worked by hand: a unit right triangle in z = 0, rays down z.
    #[test]
    fn hits_inside_and_on_edges_and_misses_outside() {
        let corners = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let down = Vec3::new(0.0, 0.0, -1.0);
        let hit = |x: f32, y: f32| ray_triangle(Vec3::new(x, y, 2.0), down, corners);
        let (t, u, v) = hit(0.25, 0.5).expect("inside");
        assert!((t - 2.0).abs() < 1e-12 && (u - 0.25).abs() < 1e-12 && (v - 0.5).abs() < 1e-12);
        assert!(hit(0.5, 0.5).is_some(), "on the hypotenuse");
        assert!(hit(0.0, 0.0).is_some(), "on a corner");
        assert!(hit(0.6, 0.6).is_none() && hit(-0.01, 0.5).is_none());
        // Behind the origin, and along the plane: no hit.
        assert!(ray_triangle(Vec3::new(0.2, 0.2, -1.0), down, corners).is_none());
        assert!(ray_triangle(Vec3::new(-1.0, 0.2, 0.0), Vec3::X, corners).is_none());
        // A slanted ray: t scales with the direction's length.
        let (t, _, _) = ray_triangle(Vec3::new(0.2, 0.2, 4.0), down * 2.0, corners).unwrap();
        assert!((t - 2.0).abs() < 1e-12);
    }
}
