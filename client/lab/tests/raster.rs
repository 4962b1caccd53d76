//! The rasterizer against the ray-traced reference: both sample pixel centres and share
//! the lighting model, so they must agree closely.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::scene::Scene;
use relief_lab::image_error::compare;
use relief_render::gbuffer::GBuffer;
use relief_render::raster::rasterize;
use relief_trace::{SceneTracer, render_reference};

fn render_both(
    scene: &Scene,
    eye: Vec3,
    target: Vec3,
    w: u32,
    h: u32,
) -> (relief_core::frame::Frame, relief_core::frame::Frame) {
    let camera = Camera::look_at(eye, target, Vec3::Y, 60.0, w, h).unwrap();
    let reference = render_reference(&SceneTracer::new(scene), &camera, 1);
    let mut gbuffer = GBuffer::new(w, h);
    let objects: Vec<_> = scene
        .objects
        .iter()
        .enumerate()
        .map(|(k, o)| (k as u32, o))
        .collect();
    rasterize(&objects, &camera, 0.01, &mut gbuffer);
    (gbuffer.shade(scene, &camera), reference)
}

#[test]
fn default_scene_matches_the_reference() {
    let scene = Scene::load("default").unwrap();
    let (frame, reference) = render_both(
        &scene,
        Vec3::new(2.0, 3.0, 9.0),
        Vec3::new(0.0, 1.0, 0.0),
        320,
        180,
    );
    let e = compare(&frame, &reference, None);
    eprintln!("raster vs reference: {e:?}");
    assert!(e.psnr_db > 48.0, "{e:?}");
    assert!(e.ssim > 0.97, "{e:?}");
    assert!(e.hole_frac < 0.01, "{e:?}");
}

#[test]
fn near_plane_clipping_keeps_the_visible_part() {
    // The eye sits just above the ground, looking along it: the ground's two huge
    // triangles cross the near plane and must be clipped, not dropped.
    let scene = Scene::load("default").unwrap();
    let (frame, reference) = render_both(
        &scene,
        Vec3::new(0.0, 0.3, 12.0),
        Vec3::new(0.0, 0.3, 0.0),
        160,
        90,
    );
    let e = compare(&frame, &reference, Some(0));
    eprintln!("ground, clipped: {e:?}");
    assert!(
        e.pixels > 160 * 40,
        "the ground should fill the lower half: {e:?}"
    );
    assert!(e.psnr_db > 48.0 && e.hole_frac < 0.01, "{e:?}");
}

/// Pixels on edges shared by two triangles belong to at least one of them: a plane of
/// many triangles seen from above, filling the frame, leaves no pixel empty.
#[test]
fn shared_edges_leave_no_cracks() {
    use relief_core::generators::Generator;
    use relief_core::scene::{SceneObject, default_lighting};
    use relief_core::shading::Specular;
    let plane = Generator::Plane {
        size: 100.0,
        divisions: 37,
    }
    .build();
    let scene = Scene {
        name: "plane".into(),
        objects: vec![SceneObject::new(
            "plane",
            plane,
            glam::DVec3::ZERO,
            Specular::default(),
        )],
        lighting: default_lighting(),
        background: Vec3::ZERO,
        fov_y_degrees: 60.0,
        path: Default::default(),
    };
    for (eye, target) in [
        (Vec3::new(0.3, 5.0, 0.2), Vec3::new(1.0, 0.0, -0.7)),
        (Vec3::new(-2.0, 1.5, 3.0), Vec3::new(5.0, 0.0, -9.0)),
    ] {
        let camera = Camera::look_at(eye, target, Vec3::Y, 50.0, 203, 157).unwrap();
        let mut gbuffer = GBuffer::new(203, 157);
        rasterize(&[(0, &scene.objects[0])], &camera, 0.01, &mut gbuffer);
        // Every pixel whose ray hits the plane (y = 0) within its extent is covered.
        let mut holes = 0;
        for y in 0..157 {
            for x in 0..203 {
                let d = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
                if d.y >= -1e-3 {
                    continue;
                }
                let hit = eye + d * (-eye.y / d.y);
                if hit.x.abs() < 49.0 && hit.z.abs() < 49.0 && !gbuffer.get(x, y).is_covered() {
                    holes += 1;
                }
            }
        }
        assert_eq!(holes, 0, "cracks seen from {eye}");
    }
}
