//! A mesh's area by the direction it faces ([`NormalCensus`]), so that how much of the
//! surface an eye sees face-on that a relief texture's parallel rays never met can be
//! told without a pass over the triangles ([`NormalCensus::unseen_share`]).
//!
//! A texture's rays see a face only from its front: a face edge-on to them, or turned
//! away, is not in the texture. Turned by `φ`, an eye sees round a curved outline a
//! band growing as `1 − cos φ` (the rim's measure, in the client); but past a sharp
//! edge a flat face that was edge-on comes into view at once, `sin φ` of its width — a
//! CAD part's side, a plinth — and the texture alone shows a hole there.
//!
//! The census keeps, per bin of normal direction ([`NORMAL_CELLS`] a side of each cube
//! face), the summed area, the area-weighted normal and the area-weighted centre: a
//! flat face's triangles share their normal, and its bin holds it exactly. An eye
//! sees each bin along the line to its centre, so a near eye's spread of rays counts:
//! an off-centre face edge-on to the texture's parallel rays (the fandisk's fin) is
//! seen face-on enough from the eye, where a convex outline turns away from it. (The
//! faces of one bin facing one way from opposite sides of the mesh are seen along the
//! line to their mean.) It is a census of facing, not of visibility: occlusion is left
//! out (a face behind another counts as seen by an eye it faces). It trusts the mesh's
//! winding (counter-clockwise seen from outside, as the shading's front faces); a mesh
//! wound the other way counts its seen faces as unseen.

use glam::{DVec3, Vec3};
use wide::f32x8;

use crate::mesh::Mesh;

/// Cells a side on each face of the cube normals are binned by: 6 × 12² directions,
/// about 7.5° each. A bin straddling the edge of what a texture sees counts whole on
/// one side, by its mean normal: on a sphere turned 10–30° the share comes within 4 %
/// of the exact one with rays off the cube's axes, 15 % with rays along one (where the
/// bins' edges lie along that edge). A flat face, one normal, is counted exactly.
pub const NORMAL_CELLS: usize = 12;

/// A mesh's area by the direction it faces (see the module docs).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NormalCensus {
    /// The bins holding any area, eight to a block, lane by lane (the last block padded
    /// with bins of no area): a client weighs every held texture against them every
    /// frame.
    blocks: Vec<Bins>,
}

/// Eight bins of a [`NormalCensus`]: their summed areas, and the components of their
/// area-weighted mean normals (unit length) and centres.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Bins {
    area: f32x8,
    normal: [f32x8; 3],
    centre: [f32x8; 3],
}

impl NormalCensus {
    /// The census of `mesh`'s triangles (degenerate ones left out); `mesh` is valid
    /// ([`Mesh::validate`]).
    pub fn of(mesh: &Mesh) -> NormalCensus {
        // Per bin: area, area × normal, area × centre.
        let mut sums = vec![(0.0f64, Vec3::ZERO, DVec3::ZERO); 6 * NORMAL_CELLS * NORMAL_CELLS];
        for t in 0..mesh.triangle_count() {
            let [a, b, c] = mesh.corners(t);
            let cross = (b - a).cross(c - a);
            let area = 0.5 * cross.length();
            if !(area > 0.0 && area.is_finite()) {
                continue;
            }
            let normal = cross / (2.0 * area);
            let sum = &mut sums[direction_cell(normal)];
            sum.0 += f64::from(area);
            sum.1 += normal * area;
            sum.2 += ((a + b + c) / 3.0).as_dvec3() * f64::from(area);
        }
        let bins: Vec<(f32, Vec3, Vec3)> = sums
            .into_iter()
            .filter(|s| s.0 > 0.0)
            .filter_map(|(area, normal, centre)| {
                Some((area as f32, normal.try_normalize()?, (centre / area).as_vec3()))
            })
            .collect();
        let blocks = bins
            .chunks(8)
            .map(|chunk| {
                let lane = |k: usize| chunk.get(k).copied().unwrap_or((0.0, Vec3::Z, Vec3::ZERO));
                let normal = |axis: usize| f32x8::new(std::array::from_fn(|k| lane(k).1[axis]));
                let centre = |axis: usize| f32x8::new(std::array::from_fn(|k| lane(k).2[axis]));
                Bins {
                    area: f32x8::new(std::array::from_fn(|k| lane(k).0)),
                    normal: [normal(0), normal(1), normal(2)],
                    centre: [centre(0), centre(1), centre(2)],
                }
            })
            .collect();
        NormalCensus { blocks }
    }

    /// Of the surface `eye` sees face-on (its projected area, occlusion left out: each
    /// bin weighted by how squarely it faces the line from `eye` to its centre), the
    /// share that faces away from every one of `rays` (the unit directions parallel
    /// texture rays travel in) or lies edge-on to them: what no such texture holds. 0
    /// when the eye sees nothing. (A face the rays meet nearly edge-on counts as seen:
    /// its few samples stretch as the view turns to it, which costs little on a flat
    /// face of one shade — counted as unseen until 4 times its size on screen, such
    /// faces flagged the fandisk's frames where its impostor matched geometry.)
    pub fn unseen_share(&self, rays: &[Vec3], eye: Vec3) -> f32 {
        let dot = |n: &[f32x8; 3], d: Vec3| n[0] * d.x + n[1] * d.y + n[2] * d.z;
        let (mut facing, mut unseen) = (f32x8::ZERO, f32x8::ZERO);
        for block in &self.blocks {
            // (The line from the eye to each bin's centre, unit: a bin at the eye is
            // seen by none.)
            let [x, y, z] = block.centre;
            let view = [x - eye.x, y - eye.y, z - eye.z];
            let length = (view[0] * view[0] + view[1] * view[1] + view[2] * view[2]).sqrt();
            let towards =
                -(block.normal[0] * view[0] + block.normal[1] * view[1] + block.normal[2] * view[2]);
            let squarely = (towards / length.max(f32x8::splat(f32::MIN_POSITIVE)))
                .max(f32x8::ZERO)
                .min(f32x8::splat(1.0));
            let projected = block.area * squarely;
            let away = (rays.iter()).fold(f32x8::splat(f32::from_bits(u32::MAX)), |away, &f| {
                away & dot(&block.normal, f).simd_ge(f32x8::ZERO)
            });
            facing += projected;
            unseen += projected & away;
        }
        let facing = facing.reduce_add();
        if facing > 0.0 {
            unseen.reduce_add() / facing
        } else {
            0.0
        }
    }
}

/// The cube-face cell a unit normal falls in ([`NORMAL_CELLS`] a side).
fn direction_cell(n: Vec3) -> usize {
    let abs = n.abs();
    let (face, u, v, major) = if abs.x >= abs.y && abs.x >= abs.z {
        (usize::from(n.x < 0.0), n.y, n.z, abs.x)
    } else if abs.y >= abs.z {
        (2 + usize::from(n.y < 0.0), n.z, n.x, abs.y)
    } else {
        (4 + usize::from(n.z < 0.0), n.x, n.y, abs.z)
    };
    let cell = |s: f32| (((s / major + 1.0) * 0.5 * NORMAL_CELLS as f32) as usize).min(NORMAL_CELLS - 1);
    (face * NORMAL_CELLS + cell(u)) * NORMAL_CELLS + cell(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generators::Generator;

    /// An eye far off along `-view`: one that sees every bin along `view`.
    fn far(view: Vec3) -> Vec3 {
        -view * 1e4
    }

    #[test]
    fn the_cuboid_faces_outwards() {
        let m = Mesh::cuboid(Vec3::ONE, Vec3::ZERO);
        for t in 0..m.triangles.len() {
            let [a, b, c] = m.corners(t);
            let n = (b - a).cross(c - a);
            assert!(n.dot((a + b + c) / 3.0) > 0.0, "triangle {t}");
        }
    }

    #[test]
    fn a_face_edge_on_to_the_texture_shows_turned_by_its_sine() {
        // A flat slab, 4 × 1 × 4: its top face edge-on to rays along −z.
        let census = NormalCensus::of(&Mesh::cuboid(Vec3::new(4.0, 1.0, 4.0), Vec3::ZERO));
        let rays = [Vec3::NEG_Z];
        assert_eq!(census.unseen_share(&rays, far(Vec3::NEG_Z)), 0.0);
        for degrees in [5.0f32, 10.0, 20.0] {
            let t = degrees.to_radians();
            let view = -Vec3::new(0.0, t.sin(), t.cos());
            // Seen: the front face (4 × 1) at cos t; not: the top (4 × 4) at sin t.
            let (front, top) = (4.0 * t.cos(), 16.0 * t.sin());
            let share = census.unseen_share(&rays, far(view));
            assert!((share - top / (front + top)).abs() < 1e-3, "{degrees}°: {share}");
        }
        // Turned the other way, the bottom shows: as unseen as the top.
        let view = -Vec3::new(0.0, -0.2f32.sin(), 0.2f32.cos());
        assert!(census.unseen_share(&rays, far(view)) > 0.4);
    }

    #[test]
    fn a_sphere_turned_shows_little_it_was_not_seen_in() {
        let census = NormalCensus::of(&Generator::Sphere { subdivisions: 5 }.build());
        // Rays off the cube's axes (on an axis, the bins' edges would lie along the
        // line between seen and unseen), and views turned from them about `axis`.
        let ray = Vec3::new(0.3, 0.2, -1.0).normalize();
        let axis = ray.any_orthonormal_vector();
        let at = |degrees: f32| {
            let turn = glam::Quat::from_axis_angle(axis, degrees.to_radians());
            census.unseen_share(&[ray], far(turn * ray))
        };
        // Exactly: the unseen lune's projection (a half-disc less a half-ellipse of
        // semi-axes 1 and cos t), over the disc's π: (1 − cos t)/2. Binned: within
        // 4–7 % here.
        for degrees in [10.0f32, 15.0, 30.0] {
            let exact = (1.0 - degrees.to_radians().cos()) / 2.0;
            let share = at(degrees);
            assert!(
                (share / exact - 1.0).abs() < 0.1,
                "{degrees}°: {share} against {exact}"
            );
        }
        assert!(at(0.0) < 0.005);
        // A partner from the far side of the view sees all the view does (for unit
        // normals the view between the two rays: a check of "every ray", not "any").
        let partner = glam::Quat::from_axis_angle(axis, 20f32.to_radians()) * ray;
        let between = glam::Quat::from_axis_angle(axis, 10f32.to_radians()) * ray;
        assert_eq!(census.unseen_share(&[ray, partner], far(between)), 0.0);
        assert!(census.unseen_share(&[ray], far(between)) > 0.0);
    }

    /// A near eye sees a face beside the object's centre that is edge-on to the
    /// texture's rays, along the line to it: a cube of side 1 three to the left of the
    /// eye's axis, rays along −z. From 10 away its right side shows, as unseen as its
    /// share of what the eye sees face-on (each face by the cosine at its centre); from
    /// far off along the same axis it does not show at all. And a sphere seen from
    /// near turns its outline away from the eye: turned 15°, less is unseen than from
    /// far.
    #[test]
    fn a_near_eye_sees_each_face_along_the_line_to_it() {
        let census = NormalCensus::of(&Mesh::cuboid(Vec3::ONE, Vec3::new(-3.0, 0.0, 0.0)));
        let (rays, eye) = ([Vec3::NEG_Z], Vec3::new(0.0, 0.0, 10.0));
        let seen = |centre: Vec3, normal: Vec3| (-normal.dot((centre - eye).normalize())).max(0.0);
        // (Faces of 1 × 1; the left, the back, the top and the bottom face away from
        // the eye, level with the cube's middle, or lie edge-on to it: 0.)
        let (right, front) = (
            seen(Vec3::new(-2.5, 0.0, 0.0), Vec3::X),
            seen(Vec3::new(-3.0, 0.0, 0.5), Vec3::Z),
        );
        let expected = right / (right + front);
        let share = census.unseen_share(&rays, eye);
        assert!(
            expected > 0.15 && (share - expected).abs() < 1e-4,
            "{share} against {expected}"
        );
        let from_far = census.unseen_share(&rays, far(Vec3::NEG_Z));
        assert!(from_far < 1e-3, "{from_far}");

        let sphere = NormalCensus::of(&Generator::Sphere { subdivisions: 5 }.build());
        let ray = Vec3::new(0.3, 0.2, -1.0).normalize();
        let turned = glam::Quat::from_axis_angle(ray.any_orthonormal_vector(), 15f32.to_radians()) * ray;
        let (near, from_far) = (
            sphere.unseen_share(&[ray], -turned * 5.0),
            sphere.unseen_share(&[ray], far(turned)),
        );
        assert!(near < 0.5 * from_far, "{near} against {from_far}");
    }
}
