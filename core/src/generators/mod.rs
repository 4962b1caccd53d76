//! Procedural meshes: the project makes its own assets instead of downloading them.
//!
//! Each generator is deterministic (fixed seeds, no global state), so a generated mesh
//! and its content hash are the same on every run and machine of the same platform.

mod knot;
mod noise;
mod plane;
mod rock;
mod sphere;
mod tree;

/// The generators' deterministic random numbers, for whoever else needs the same (a
/// test relay's lost packets).
pub use noise::SplitMix64;

use serde::Deserialize;

use crate::mesh::Mesh;

/// A procedural mesh and its parameters, as written in a scene file
/// (`generator = { kind = "sphere", subdivisions = 4 }`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Generator {
    /// A unit icosphere: smooth and convex.
    Sphere { subdivisions: u32 },
    /// A (p, q) torus knot tube in the xy plane, radius ≤ 1: deeply concave and
    /// self-occluding.
    Knot {
        p: u32,
        q: u32,
        segments: u32,
        sides: u32,
        tube_radius: f32,
    },
    /// A branching tree with leaf quads: many thin disconnected parts. Height ≈ 2.
    Tree { seed: u64, depth: u32, leaves: u32 },
    /// A rugged rock: a displaced cube-sphere with `6 · 2 · resolution²` triangles.
    Rock { resolution: u32, seed: u64 },
    /// A square in the xz plane facing +y, `divisions²` quads.
    Plane { size: f32, divisions: u32 },
}

/// Caps that keep a typo in a scene file from asking for billions of triangles.
const MAX_SUBDIVISIONS: u32 = 8;
const MAX_GRID: u32 = 2048;
const MAX_TREE_DEPTH: u32 = 9;

/// A generator parameter out of its range: the message names the parameter and the range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct GeneratorError(pub &'static str);

impl Generator {
    /// Checks parameter ranges; the error names the parameter.
    pub fn validate(&self) -> Result<(), GeneratorError> {
        let check = |ok: bool, what: &'static str| if ok { Ok(()) } else { Err(GeneratorError(what)) };
        match *self {
            Generator::Sphere { subdivisions } => check(
                subdivisions <= MAX_SUBDIVISIONS,
                "sphere: subdivisions must be at most 8",
            ),
            Generator::Knot {
                p,
                q,
                segments,
                sides,
                tube_radius,
            } => {
                check(p >= 1 && q >= 1, "knot: p and q must be at least 1")?;
                check(
                    (8..=100_000).contains(&segments) && (3..=1024).contains(&sides),
                    "knot: segments must be in 8..=100000 and sides in 3..=1024",
                )?;
                check(
                    tube_radius.is_finite() && tube_radius > 0.0 && tube_radius < 1.0,
                    "knot: tube_radius must be in (0, 1)",
                )
            }
            Generator::Tree { depth, leaves, .. } => check(
                depth <= MAX_TREE_DEPTH && leaves <= 256,
                "tree: depth must be at most 9 and leaves at most 256",
            ),
            Generator::Rock { resolution, .. } => check(
                (1..=MAX_GRID).contains(&resolution),
                "rock: resolution must be in 1..=2048",
            ),
            Generator::Plane { size, divisions } => {
                check(size.is_finite() && size > 0.0, "plane: size must be positive")?;
                check(
                    (1..=MAX_GRID).contains(&divisions),
                    "plane: divisions must be in 1..=2048",
                )
            }
        }
    }

    /// Builds the mesh in object space. Call [`Generator::validate`] first.
    /// The triangles [`Generator::build`] makes, worked out from the parameters alone:
    /// what a scene costs is known before it is built.
    pub fn triangles(&self) -> u64 {
        let u = u64::from;
        match *self {
            Generator::Sphere { subdivisions } => 20 * 4u64.saturating_pow(subdivisions),
            Generator::Knot { segments, sides, .. } => 2 * u(segments) * u(sides),
            Generator::Tree { depth, leaves, .. } => tree::triangles(depth, leaves),
            Generator::Rock { resolution, .. } => 12 * u(resolution) * u(resolution),
            Generator::Plane { divisions, .. } => 2 * u(divisions) * u(divisions),
        }
    }

    pub fn build(&self) -> Mesh {
        match *self {
            Generator::Sphere { subdivisions } => sphere::icosphere(subdivisions),
            Generator::Knot {
                p,
                q,
                segments,
                sides,
                tube_radius,
            } => knot::torus_knot(p, q, segments, sides, tube_radius),
            Generator::Tree { seed, depth, leaves } => tree::tree(seed, depth, leaves),
            Generator::Rock { resolution, seed } => rock::rock(resolution, seed),
            Generator::Plane { size, divisions } => plane::plane(size, divisions),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_sound(mesh: &Mesh) {
        mesh.validate().unwrap();
        let normals = mesh.normals.as_ref().unwrap();
        assert!(normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-3));
    }

    /// The count worked out from the parameters is the count built, for every kind.
    #[test]
    fn triangles_are_known_before_building() {
        let generators = [
            Generator::Sphere { subdivisions: 3 },
            Generator::Knot {
                p: 2,
                q: 3,
                segments: 40,
                sides: 7,
                tube_radius: 0.2,
            },
            Generator::Tree {
                seed: 4,
                depth: 3,
                leaves: 5,
            },
            Generator::Tree {
                seed: 4,
                depth: 0,
                leaves: 0,
            },
            Generator::Rock {
                resolution: 9,
                seed: 1,
            },
            Generator::Plane {
                size: 2.0,
                divisions: 5,
            },
        ];
        for generator in generators {
            assert_eq!(
                generator.triangles(),
                generator.build().triangle_count() as u64,
                "{generator:?}"
            );
        }
    }

    #[test]
    fn generators_make_valid_meshes_of_the_promised_size() {
        let sphere = Generator::Sphere { subdivisions: 2 }.build();
        assert_eq!(sphere.triangle_count(), 320);
        assert_sound(&sphere);
        let rock = Generator::Rock {
            resolution: 8,
            seed: 1,
        }
        .build();
        assert_eq!(rock.triangle_count(), 6 * 2 * 64);
        assert_sound(&rock);
        let knot = Generator::Knot {
            p: 2,
            q: 3,
            segments: 64,
            sides: 8,
            tube_radius: 0.3,
        }
        .build();
        assert_eq!(knot.triangle_count(), 64 * 8 * 2);
        assert_sound(&knot);
        let tree = Generator::Tree {
            seed: 7,
            depth: 3,
            leaves: 4,
        }
        .build();
        assert_sound(&tree);
        assert!(tree.materials.len() == 2);
        let plane = Generator::Plane {
            size: 2.0,
            divisions: 3,
        }
        .build();
        assert_eq!(plane.triangle_count(), 18);
        assert_sound(&plane);
        assert!(plane.face_normal(0).abs_diff_eq(glam::Vec3::Y, 1e-6));
        // Solids are closed (no back face can show); the plane and the tree's leaves
        // are not.
        let closed = [&sphere, &rock, &knot, &tree, &plane].map(|m| m.is_closed());
        assert_eq!(closed, [true, true, true, false, false]);
        // One triangle fewer opens a solid.
        let mut holed = sphere.clone();
        holed.triangles.pop();
        assert!(!holed.is_closed());
        // ... but leaves it nearly all paired: its rim is that triangle's three edges,
        // where a sheet is mostly rim (the plane's 3×3 cells: 12 of 33 edges).
        let rim = |m: &Mesh| m.edge_census().rim_share;
        assert_eq!(rim(&holed), 3.0 / (sphere.triangle_count() as f32 * 1.5));
        assert_eq!(rim(&plane), 12.0 / 33.0);
        assert!(rim(&tree) > 0.5, "the tree's leaves: {}", rim(&tree));
        assert_eq!(rim(&sphere), 0.0);
    }

    #[test]
    fn outward_winding_on_closed_shapes() {
        for mesh in [
            Generator::Sphere { subdivisions: 1 }.build(),
            Generator::Rock {
                resolution: 4,
                seed: 3,
            }
            .build(),
        ] {
            for t in 0..mesh.triangle_count() {
                let centre = mesh.corners(t).iter().copied().sum::<glam::Vec3>() / 3.0;
                assert!(
                    mesh.face_normal(t).dot(centre) > 0.0,
                    "triangle {t} faces inwards"
                );
            }
        }
    }

    #[test]
    fn rejects_absurd_parameters() {
        assert!(Generator::Sphere { subdivisions: 20 }.validate().is_err());
        assert!(
            Generator::Rock {
                resolution: 0,
                seed: 0
            }
            .validate()
            .is_err()
        );
        assert!(
            Generator::Plane {
                size: f32::NAN,
                divisions: 1
            }
            .validate()
            .is_err()
        );
    }
}
