//! Placements (a scene file's `instances`): a placement traces and draws as the same
//! mesh transformed by hand, and all the placements of an object share one mesh, one
//! BVH and (in its frame) its textures.

use std::sync::Arc;

use glam::DVec3;

use relief_core::camera::Camera;
use relief_core::frame::NO_OBJECT;
use relief_core::relief::{DepthBits, SourceProjection};
use relief_core::scene::{Scene, SceneObject};
use relief_render::gbuffer::GBuffer;
use relief_render::impostor::{Faces, Impostor};
use relief_render::raster::rasterize;
use relief_render::warp::{Prewarped, Variant};
use relief_trace::bake::bake;
use relief_trace::reference::render_reference;
use relief_trace::tracer::{ObjectTracer, SceneTracer};

fn parse(text: &str) -> Scene {
    Scene::parse(text).expect("scene")
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

/// The placement only moved bakes what the same mesh moved by hand bakes, to the bit:
/// its mesh is the hand-made object's, its origin the same to rounding.
#[test]
fn a_moved_placement_bakes_as_by_hand() {
    let (placed, by_hand) = scenes();
    let (p, h) = (
        ObjectTracer::new(&placed.objects[0]),
        ObjectTracer::new(&by_hand.objects[0]),
    );
    assert_eq!(p.object.mesh.positions, h.object.mesh.positions);
    assert!(p.object.origin.abs_diff_eq(h.object.origin, 1e-12));
    let world_eye = DVec3::new(-2.0, 3.0, 7.0);
    for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
        let texture = |t: &ObjectTracer| {
            bake(
                t,
                t.object.to_local(world_eye),
                96,
                DepthBits::Sixteen,
                projection,
            )
            .expect("bake")
        };
        assert_eq!(texture(&p), texture(&h), "{projection:?}");
    }
}

/// A frame of the knots as the client draws them — as geometry, and as impostors
/// baked in each object's frame and warped there — with the turned and scaled
/// placement sharing the mesh of the moved one, against the same frame of the knots
/// written out by hand: the same pixels covered, the same depths in the world's
/// metres (each object's depths scaled out of its frame), the same colours (its
/// normals turned into the world) to within the warps' own error.
#[test]
fn placements_draw_as_by_hand() {
    let (placed, by_hand) = scenes();
    assert!(placed.objects[0].shares_mesh(&placed.objects[1]));
    let camera = view();
    let geometry = |scene: &Scene| {
        let mut gbuffer = GBuffer::new(camera.width, camera.height);
        let objects: Vec<(u32, &SceneObject)> = (0..).zip(&scene.objects).collect();
        rasterize(&objects, &camera, 0.01, &mut gbuffer);
        gbuffer
    };
    let impostors = |scene: &Scene| {
        let mut gbuffer = GBuffer::new(camera.width, camera.height);
        for (k, object) in (0..).zip(&scene.objects) {
            let local = object.local_camera(&camera);
            let tracer = ObjectTracer::new(object);
            // Baked from an eye the camera has since moved from (about 6°).
            let eye = object.to_local(DVec3::new(0.7, 2.4, 5.9));
            let texture = bake(
                &tracer,
                eye,
                256,
                DepthBits::Sixteen,
                SourceProjection::Perspective,
            )
            .expect("bake");
            let impostor = Impostor::new(texture).with_faces(Faces::of(object));
            Prewarped::new(Variant::Interleaved, &impostor, &local)
                .and_then(|p| p.in_world(object.depth_scale()))
                .expect("warp")
                .draw(&impostor, k, &local, &mut gbuffer);
        }
        gbuffer
    };
    for (what, draw, least_db) in [
        ("geometry", &geometry as &dyn Fn(&Scene) -> GBuffer, 40.0),
        ("impostors", &impostors, 30.0),
    ] {
        let (a, b) = (draw(&placed), draw(&by_hand));
        let (mut both, mut either, mut depth_off) = (0, 0, 0);
        for y in 0..camera.height {
            for x in 0..camera.width {
                let (p, q) = (a.get(x, y), b.get(x, y));
                let (pa, qa) = (p.object != NO_OBJECT, q.object != NO_OBJECT);
                either += usize::from(pa || qa);
                if pa && qa {
                    both += 1;
                    depth_off += usize::from((p.depth - q.depth).abs() > 0.01 * q.depth);
                }
            }
        }
        assert!(both > 2000, "{what}: {both} pixels");
        assert!(
            either - both <= both / 50,
            "{what}: {either} covered by either, {both} by both"
        );
        assert!(
            depth_off <= both / 100,
            "{what}: {depth_off} of {both} depths differ by 1 %"
        );
        let (fa, fb) = (a.shade(&placed, &camera), b.shade(&by_hand, &camera));
        let squared: f64 = (fa.color.iter().zip(&fb.color))
            .flat_map(|(p, q)| p.iter().zip(q).map(|(x, y)| (*x as f64 - *y as f64).powi(2)))
            .sum();
        let psnr = 10.0 * (255.0f64.powi(2) * (3 * either) as f64 / squared.max(1e-9)).log10();
        assert!(psnr >= least_db, "{what}: {psnr:.1} dB over the knots' pixels");
    }
}

/// The camera of the frames compared.
fn view() -> Camera {
    Camera::look_at(
        DVec3::new(0.0, 2.0, 6.0),
        DVec3::new(0.0, 1.0, -0.5),
        glam::Vec3::Y,
        60.0,
        320,
        240,
    )
    .expect("camera")
}

/// Placements share one mesh and one BVH, however they are moved, turned or scaled.
/// The reference of the placed scene is the hand-made
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
    assert!(
        Arc::ptr_eq(bvh(0), bvh(1)) && Arc::ptr_eq(bvh(0), bvh(2)),
        "placements share a BVH, moved or scaled"
    );
    let camera = view();
    let (a, b) = (
        render_reference(&SceneTracer::new(&placed), &camera, 1),
        render_reference(&SceneTracer::new(&by_hand), &camera, 1),
    );
    let drawn = a.object.iter().filter(|&&o| o != NO_OBJECT).count();
    assert!(drawn > 1000, "the knots cover {drawn} pixels");
    let off = a
        .color
        .iter()
        .zip(&b.color)
        .filter(|(x, y)| x.iter().zip(y.iter()).any(|(p, q)| p.abs_diff(*q) > 1))
        .count();
    assert!(off <= drawn / 200, "{off} of {drawn} pixels differ");
}
