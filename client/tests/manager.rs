//! The impostor manager with the in-process generator: textures arrive without the
//! frame loop waiting, and a still eye redraws sprites instead of warping.

use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use tokio::sync::mpsc::unbounded_channel;

use relief_client::gbuffer::GBuffer;
use relief_client::manager::{Config, Manager, Show};
use relief_client::source::spawn_local;
use relief_core::camera::Camera;
use relief_core::scene::Scene;

#[test]
fn still_eyes_draw_sprites_and_moving_eyes_warp() {
    let scene = Arc::new(Scene::load("default").unwrap());
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    spawn_local(scene.clone(), commands_rx, arrivals_tx);
    let mut manager = Manager::new(&scene, Config::default(), commands_tx, arrivals_rx);
    let camera = Camera::look_at(
        Vec3::new(2.0, 3.0, 9.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::Y,
        60.0,
        160,
        90,
    )
    .unwrap();
    assert!(
        manager.warm_up(&scene, &camera, Duration::from_secs(60)),
        "textures did not arrive"
    );
    let shows = manager.frame(&scene, &camera, 0.0);
    let impostors = shows
        .iter()
        .filter(|s| matches!(s, Show::Impostor { .. }))
        .count() as u64;
    assert!(impostors >= 3, "{shows:?}");
    let mut gbuffer = GBuffer::new(160, 90);
    let first = manager.render(&scene, &shows, &camera, &mut gbuffer);
    assert_eq!((manager.counters.warps, manager.counters.sprites), (impostors, 0));
    // The same eye: every impostor is redrawn from its sprite, identically.
    let shows = manager.frame(&scene, &camera, 0.1);
    let second = manager.render(&scene, &shows, &camera, &mut gbuffer);
    assert_eq!(manager.counters.sprites, impostors);
    assert_eq!(first, second);
    // A step of many pixels' angle: warped again.
    let moved = Camera::look_at(
        Vec3::new(2.6, 3.0, 9.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::Y,
        60.0,
        160,
        90,
    )
    .unwrap();
    let shows = manager.frame(&scene, &moved, 0.2);
    manager.render(&scene, &shows, &moved, &mut gbuffer);
    assert!(manager.counters.warps > impostors);
}
