//! The error predictions against what real warps do.

use relief_client::evaluate::Solo;
use relief_client::impostor::Impostor;
use relief_client::metrics::critical::{CriticalPoints, measured_gap};
use relief_client::metrics::schaufler::{needs_finer_texture, sprite_still_valid};
use relief_client::warp::params::WarpParams;
use relief_core::relief::DepthBits;
use relief_core::scene::Scene;

/// The critical pair's predicted gap never exceeds the widest real gap (it is one of
/// the pairs) and grows with the angle as the real one does; the worst of the 8×8
/// regions' critical pairs predicts the real gap within 10 % on a convex and on a
/// self-occluding object (the single pair can under-predict several times).
#[test]
fn critical_point_prediction_tracks_the_measured_gap() {
    let scene = Scene::load("default").unwrap();
    for (name, factor) in [("sphere", 1.1f32), ("knot", 1.1)] {
        let solo = Solo::new(&scene, name, 3.0).unwrap();
        let texture = Impostor::new(solo.bake(solo.eye(0.0), 128, DepthBits::Eight).unwrap()).texture;
        let critical = CriticalPoints::find(&texture, 8, 8);
        let mut last = (0.0f32, 0.0f32);
        for angle in [5.0f32, 10.0, 20.0, 40.0] {
            let params = WarpParams::new(&texture, solo.eye(angle)).unwrap();
            let predicted = critical.global_gap(&params);
            let measured = measured_gap(&texture, &params);
            eprintln!(
                "{name} {angle}°: predicted {predicted:.2} (worst region {:.2}), measured {measured:.2} texels",
                critical.worst_region_gap(&params)
            );
            assert!(
                predicted <= measured + 1e-3,
                "{name} {angle}°: {predicted} > {measured}"
            );
            let worst = critical.worst_region_gap(&params);
            assert!(
                measured <= factor * worst + 0.2,
                "{name} {angle}°: {measured} vs {worst}"
            );
            assert!(
                predicted >= last.0 && measured > last.1,
                "{name} {angle}°: not growing"
            );
            assert!(critical.region_gap(&params) >= predicted);
            last = (predicted, measured);
        }
        assert!(last.0 > 1.0, "{name}: the prediction never grew: {last:?}");
    }
}

#[test]
fn schaufler_tests_on_an_orbit() {
    let scene = Scene::load("default").unwrap();
    let solo = Solo::new(&scene, "sphere", 3.0).unwrap();
    let bounds = solo.scene.objects[0].bounds;
    let source = solo.eye(0.0);
    let camera = solo.camera(source, 512);
    assert!(sprite_still_valid(&bounds, source, &camera));
    let turned = solo.camera(solo.eye(5.0), 512);
    assert!(!sprite_still_valid(&bounds, source, &turned), "5° is many pixels");
    // 64 texels across an object that covers ~230 of 512 pixels is too coarse; 512 is not.
    let coarse = solo.bake(source, 64, DepthBits::Eight).unwrap();
    let fine = solo.bake(source, 512, DepthBits::Eight).unwrap();
    assert!(needs_finer_texture(&coarse.camera, &camera, 1.0));
    assert!(!needs_finer_texture(&fine.camera, &camera, 1.0));
}
