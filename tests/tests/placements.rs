//! Placements (a scene file's `instances`): a placement bakes, traces and draws as the
//! same mesh transformed by hand, and its placements share one mesh and one BVH.

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;

use relief_core::camera::Camera;
use relief_core::reach::Reach;
use relief_core::relief::{DepthBits, SourceProjection};
use relief_core::scene::{Scene, SceneLimits, file};
use relief_trace::bake::bake;
use relief_trace::reference::render_reference;
use relief_trace::tracer::SceneTracer;

fn parse(text: &str) -> Scene {
    file::parse(
        text,
        "test",
        Path::new("."),
        Reach::Anywhere,
        &SceneLimits::default(),
    )
    .expect("scene")
}

const KNOT: &str =
    r#"generator = { kind = "knot", p = 2, q = 3, segments = 180, sides = 12, tube_radius = 0.28 }"#;

/// The knot placed twice by `instances` (once moved, once moved, turned and scaled),
/// and the same two written out by hand: the second turned 90° about y and scaled by
/// 0.5 after its own scale of 1.2 and translate of (3, 1.3, 0), which goes to
/// (0, 0.65, −1.5) before the placement's translate.
fn scenes() -> (Scene, Scene) {
    let placed = parse(&format!(
        r#"
        [[objects]]
        name = "knot"
        {KNOT}
        translate = [3, 1.3, 0]
        scale = 1.2
        instances = [
          {{ translate = [-2, 0, 0] }},
          {{ translate = [-1, 0, 0], rotate_deg = [0, 90, 0], scale = 0.5 }},
        ]
        "#
    ));
    let by_hand = parse(&format!(
        r#"
        [[objects]]
        name = "moved"
        {KNOT}
        translate = [1, 1.3, 0]
        scale = 1.2
        [[objects]]
        name = "turned"
        {KNOT}
        translate = [-1, 0.65, -1.5]
        rotate_deg = [0, 90, 0]
        scale = 0.6
        "#
    ));
    (placed, by_hand)
}

/// Each placement's mesh, in its own frame, is the hand-made object's to the bit, its
/// frame's origin the same to rounding; so a bake from one eye in the world gives the
/// same texture (depth levels within one, where the eye's f32 offset rounds apart).
#[test]
fn a_placement_bakes_as_the_mesh_transformed_by_hand() {
    let (placed, by_hand) = scenes();
    let (placed_tracer, hand_tracer) = (SceneTracer::new(&placed), SceneTracer::new(&by_hand));
    let world_eye = DVec3::new(-2.0, 3.0, 7.0);
    for k in 0..2 {
        let (p, h) = (&placed_tracer.objects[k], &hand_tracer.objects[k]);
        assert_eq!(
            p.object.mesh.positions, h.object.mesh.positions,
            "{}: the mesh as by hand",
            p.object.name
        );
        assert!(
            p.object.origin.abs_diff_eq(h.object.origin, 1e-12),
            "{}: origin {} against {}",
            p.object.name,
            p.object.origin,
            h.object.origin
        );
        for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
            let texture = |t| {
                let tracer: &relief_trace::tracer::ObjectTracer = t;
                let eye = tracer.object.to_local(world_eye);
                bake(tracer, eye, 96, DepthBits::Sixteen, projection).expect("bake")
            };
            let (a, b) = (texture(p), texture(h));
            let apart = a
                .depth
                .iter()
                .zip(&b.depth)
                .filter(|(x, y)| x.abs_diff(**y) > 1)
                .count();
            assert_eq!(
                apart, 0,
                "{} {projection:?}: texels more than a level apart",
                p.object.name
            );
            let same_surface = a.depth.iter().zip(&b.depth).filter(|(x, y)| x == y).count();
            assert!(
                same_surface * 10 >= a.depth.len() * 9,
                "{same_surface} of {}",
                a.depth.len()
            );
        }
    }
}

/// Placements differing only in where they stand share one mesh and one BVH; a
/// turned one has its own. The reference of the placed scene is the hand-made
/// scene's, pixel for pixel (to a level of colour).
#[test]
fn placements_share_a_bvh_and_trace_as_by_hand() {
    let (placed, by_hand) = scenes();
    let three = parse(&format!(
        r#"
        [[objects]]
        name = "knot"
        {KNOT}
        instances = [{{}}, {{ translate = [4, 0, 0] }}, {{ translate = [0, 0, 4], scale = 2 }}]
        "#
    ));
    let tracer = SceneTracer::new(&three);
    let bvh = |k: usize| &tracer.objects[k].bvh;
    assert!(Arc::ptr_eq(bvh(0), bvh(1)), "moved placements share a BVH");
    assert!(!Arc::ptr_eq(bvh(0), bvh(2)), "a scaled one has its own");
    let camera = Camera::look_at(
        DVec3::new(0.0, 2.0, 6.0),
        DVec3::new(0.0, 1.0, -0.5),
        glam::Vec3::Y,
        60.0,
        320,
        240,
    )
    .expect("camera");
    let (a, b) = (
        render_reference(&SceneTracer::new(&placed), &camera, 1),
        render_reference(&SceneTracer::new(&by_hand), &camera, 1),
    );
    let drawn = a
        .object
        .iter()
        .filter(|&&o| o != relief_core::frame::NO_OBJECT)
        .count();
    assert!(drawn > 1000, "the knots cover {drawn} pixels");
    let off = a
        .color
        .iter()
        .zip(&b.color)
        .filter(|(x, y)| x.iter().zip(y.iter()).any(|(p, q)| p.abs_diff(*q) > 1))
        .count();
    assert!(off <= drawn / 200, "{off} of {drawn} pixels differ");
}
