//! The rasterizer against the ray-traced reference: both sample pixel centres and share
//! the lighting model, so they must agree closely.

use glam::Vec3;

use relief_client::gbuffer::GBuffer;
use relief_client::metrics::image::compare;
use relief_client::raster::rasterize;
use relief_core::camera::Camera;
use relief_core::scene::Scene;
use relief_worker::{SceneTracer, render_reference};

fn render_both(
    scene: &Scene,
    eye: Vec3,
    target: Vec3,
    w: u32,
    h: u32,
) -> (relief_core::frame::Frame, relief_core::frame::Frame) {
    let camera = Camera::look_at(eye, target, Vec3::Y, 60.0, w, h).unwrap();
    let reference = render_reference(&SceneTracer::new(scene), &camera);
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
