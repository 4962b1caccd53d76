//! The impostor manager with the in-process generator: textures arrive without the
//! frame loop waiting, a still eye redraws sprites instead of warping, predictions lead
//! the motion, textures far too coarse for the screen give way to geometry, and the
//! local generator serves requests for now in the order asked.

use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender, unbounded_channel};

use relief_client::manager::{
    Arrival, Command, Config, Manager, ReadyTexture, Show, TextureRequest, texture_ladder,
};
use relief_client::source::spawn_local;
use relief_core::camera::Camera;
use relief_core::scene::Scene;
use relief_render::gbuffer::GBuffer;

#[test]
fn still_eyes_draw_sprites_and_moving_eyes_warp() {
    let scene = Arc::new(Scene::load("default").unwrap());
    let mut manager = served_locally(&scene, Config::default());
    // A 160×90 view from `eye` towards `at`.
    let view = |eye: Vec3, at: Vec3| Camera::look_at(eye, at, Vec3::Y, 60.0, 160, 90).unwrap();
    let camera = view(Vec3::new(2.0, 3.0, 9.0), Vec3::new(0.0, 1.0, 0.0));
    assert!(
        manager.warm_up(&scene, &[camera], Duration::from_secs(60)),
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
    let moved = view(Vec3::new(2.6, 3.0, 9.0), Vec3::new(0.0, 1.0, 0.0));
    let shows = manager.frame(&scene, &moved, 0.2);
    manager.render(&scene, &shows, &moved, &mut gbuffer);
    assert_eq!(manager.counters.warps, 2 * impostors);
    // After that step no image was kept (the eye was moving): the first still frame
    // warps again, and keeps its images; the next one redraws them.
    let shows = manager.frame(&scene, &moved, 0.3);
    manager.render(&scene, &shows, &moved, &mut gbuffer);
    assert_eq!(manager.counters.warps, 3 * impostors);
    let shows = manager.frame(&scene, &moved, 0.4);
    manager.render(&scene, &shows, &moved, &mut gbuffer);
    assert_eq!(manager.counters.sprites, 2 * impostors);
    // The eye still, the view turned by a few pixels: the kept images would land where
    // the objects were, so every impostor is warped again.
    let turned = view(Vec3::new(2.6, 3.0, 9.0), Vec3::new(0.5, 1.0, 0.0));
    let shows = manager.frame(&scene, &turned, 0.5);
    manager.render(&scene, &shows, &turned, &mut gbuffer);
    assert_eq!(
        (manager.counters.warps, manager.counters.sprites),
        (4 * impostors, 2 * impostors)
    );
}

/// A manager of `scene` whose textures the in-process generator makes.
fn served_locally(scene: &Arc<Scene>, config: Config) -> Manager {
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    spawn_local(scene.clone(), commands_rx, arrivals_tx);
    Manager::new(scene, config, commands_tx, arrivals_rx)
}

/// The scanned bunny of `../shared/models` (CI has `../shared` beside the clone).
fn shared_bunny() -> std::path::PathBuf {
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/models");
    let bunny = models.join("stanford-bunny.obj");
    assert!(
        bunny.is_file(),
        "{} is missing (CI has ../shared beside the clone)",
        bunny.display()
    );
    bunny
}

/// The index of `name` in `scene`.
fn index(scene: &Scene, name: &str) -> usize {
    scene.objects.iter().position(|o| o.name == name).unwrap()
}

/// The default settings, but no object drawn as geometry in the stead of a stale
/// texture: for the tests of what a stale object does.
fn without_stand_ins() -> Config {
    Config {
        stand_in_triangles: 0,
        ..Config::default()
    }
}

/// A manager wired to the test: the channel its requests go out on, and the one the
/// test answers them on.
fn wired(scene: &Scene, config: Config) -> (Manager, UnboundedReceiver<Command>, UnboundedSender<Arrival>) {
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, arrivals_rx) = unbounded_channel();
    (
        Manager::new(scene, config, commands_tx, arrivals_rx),
        commands_rx,
        arrivals_tx,
    )
}

/// A manager whose requests nobody answers, and the channel they go out on.
fn unanswered(scene: &Scene, config: Config) -> (Manager, UnboundedReceiver<Command>) {
    let (manager, commands, _) = wired(scene, config);
    (manager, commands)
}

/// The final texture `ready` arrives for request `id`.
fn arrive(arrivals: &UnboundedSender<Arrival>, id: u64, ready: ReadyTexture) {
    let texture = Box::new(ready);
    arrivals
        .send(Arrival::Texture {
            id,
            texture,
            is_final: true,
        })
        .unwrap();
}

/// The first request for now among the commands sent so far (the others are dropped).
fn request_now(commands: &mut UnboundedReceiver<Command>) -> TextureRequest {
    std::iter::from_fn(|| commands.try_recv().ok())
        .find_map(|c| match c {
            Command::Request(r) if r.needed_in_ms.is_none() => Some(r),
            _ => None,
        })
        .expect("a request for now")
}

/// The eye 6 m from `centre`, `angle` radians round it, 0.5 m above.
fn around(centre: Vec3, angle: f32) -> Vec3 {
    centre + Vec3::new(6.0 * angle.cos(), 0.5, 6.0 * angle.sin())
}

/// A 320×180 camera [`around`] `centre`, `degrees` round it, looking at it.
fn camera_round(centre: Vec3, degrees: f32) -> Camera {
    Camera::look_at(
        around(centre, degrees.to_radians()),
        centre,
        Vec3::Y,
        60.0,
        320,
        180,
    )
    .unwrap()
}

/// Draws a frame from `eye` (looking at `centre`) at `t`, and returns the eyes of the
/// requests for `object` it sent — the predicted ones or those needed now.
fn requests_from_frame(
    manager: &mut Manager,
    commands: &mut UnboundedReceiver<Command>,
    scene: &Scene,
    (eye, centre, t): (Vec3, Vec3, f64),
    object: &str,
    predicted: bool,
) -> Vec<Vec3> {
    let camera = Camera::look_at(eye, centre, Vec3::Y, 60.0, 320, 180).unwrap();
    manager.frame(scene, &camera, t);
    let mut eyes = Vec::new();
    while let Ok(command) = commands.try_recv() {
        if let Command::Request(r) = command
            && r.object == object
            && r.needed_in_ms.is_some() == predicted
        {
            // (Requests give eyes in the object's frame.)
            eyes.push(scene.object(object).unwrap().to_world(r.eye).as_vec3());
        }
    }
    eyes
}

#[test]
fn predicted_textures_are_made_for_eyes_past_the_predicted_one() {
    let scene = Scene::load("default").unwrap();
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    let config = Config::default();
    let horizon = config.initial_latency + 0.05;
    let (mut manager, mut commands) = unanswered(&scene, config);
    // Orbit the sphere at 6 m, 30°/s, 30 frames a second.
    let rate = 30f32.to_radians();
    let eye_at = |t: f32| around(centre, rate * t);
    let mut predicted = Vec::new();
    for frame in 0..10 {
        let t = frame as f32 / 30.0;
        let sent = (eye_at(t), centre, t as f64);
        for eye in requests_from_frame(&mut manager, &mut commands, &scene, sent, "sphere", true) {
            predicted.push((t, eye));
        }
    }
    let (t, eye) = *predicted.last().expect("no predicted request for the sphere");
    // The angle from the sphere's centre between the eye at `t` and `eye`, against the
    // turn to the eye predicted for the round trip: the texture is made further on.
    let turn = |a: Vec3| (eye_at(t) - centre).angle_between(a - centre);
    let future = eye_at(t + horizon as f32);
    assert!(
        turn(eye) > turn(future) + 0.5f32.to_radians(),
        "asked for {:.2}° ahead, the eye will be {:.2}° ahead",
        turn(eye).to_degrees(),
        turn(future).to_degrees()
    );
    // … but not beyond the orbit: the same distance from the centre.
    assert!((eye.distance(centre) - future.distance(centre)).abs() < 0.05);
}

/// An eye heading straight for the sphere, near enough by the horizon to draw it as
/// geometry but not yet when a texture asked for now could come back: the texture is
/// asked ahead for the last eye before that, not for none.
#[test]
fn an_object_too_near_by_the_horizon_is_predicted_for_before_it() {
    use relief_render::geometry::{GeometryReason, geometry_reason};

    let scene = Scene::load("default").unwrap();
    let sphere = scene.object("sphere").unwrap();
    let centre = sphere.world_bounds().center();
    // A round trip of 2 s, so that the horizon is 0.55 s past it.
    let config = Config {
        initial_latency: 2.0,
        ..Config::default()
    };
    let (mut manager, mut commands) = unanswered(&scene, config);
    // 1 m/s towards the centre from 4.4 m: too near by the horizon from the first frame
    // (4.4 − 2.55 m is within the sphere's near margin), not 2 s ahead.
    let eye_at = |t: f32| centre + Vec3::new(0.0, 0.0, 4.4 - t);
    let too_near = |eye: Vec3| geometry_reason(sphere, eye.as_dvec3()) == Some(GeometryReason::TooNear);
    assert!(too_near(eye_at(2.55)) && !too_near(eye_at(0.3 + 2.0)));
    let mut predicted = Vec::new();
    for frame in 0..10 {
        let t = frame as f32 / 30.0;
        predicted.extend(requests_from_frame(
            &mut manager,
            &mut commands,
            &scene,
            (eye_at(t), centre, t as f64),
            "sphere",
            true,
        ));
    }
    let eye = *predicted.last().expect("nothing asked ahead for the sphere");
    // (The lead takes it no nearer: a texture from nearer still would be drawn as
    // geometry.)
    assert!(!too_near(eye), "asked ahead for {eye}, too near to be shown");
    // (At least a round trip ahead: a texture asked for nearer by would come too late.)
    let round_trip_ahead = eye_at(0.3 + 2.0).distance(centre);
    assert!(
        eye.distance(centre) <= round_trip_ahead,
        "asked for {eye}: not a round trip ahead"
    );
}

#[test]
fn a_texture_far_too_coarse_for_the_screen_gives_way_to_geometry() {
    let scene = Arc::new(Scene::load("default").unwrap());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let mut manager = served_locally(&scene, Config::default());
    let eye = centre + Vec3::new(0.0, 0.5, 8.0);
    // Textures sized for a small screen …
    let small = Camera::look_at(eye, centre, Vec3::Y, 60.0, 64, 36).unwrap();
    assert!(manager.warm_up(&scene, &[small], Duration::from_secs(60)));
    assert!(matches!(
        manager.frame(&scene, &small, 0.0)[sphere],
        Show::Impostor { .. }
    ));
    // … are not stretched over a screen twenty times larger from the same eye.
    let large = Camera::look_at(eye, centre, Vec3::Y, 60.0, 1280, 720).unwrap();
    assert_eq!(manager.frame(&scene, &large, 0.1)[sphere], Show::Geometry);
}

/// A texture magnified past `REFINE_TEXEL` (the eye drawing near, or here the screen
/// growing) is still shown, and a finer one asked for at once; at the size it was made
/// for, none is.
#[test]
fn a_texture_magnified_past_a_pixel_is_replaced_while_shown() {
    use relief_client::manager::policy::{COARSEST_SHOWN, REFINE_TEXEL};
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let sphere = index(&scene, "sphere");
    let config = Config {
        predict: false,
        ..Config::default()
    };
    let (mut manager, mut commands, arrivals) = wired(&scene, config);
    let centre = scene.objects[sphere].world_bounds().center();
    let eye = centre + Vec3::new(0.0, 1.0, 6.0);
    let camera = |width: u32| Camera::look_at(eye, centre, Vec3::Y, 60.0, width, width * 9 / 16).unwrap();
    // The requests for now a frame on a screen `width` pixels wide makes, and how it
    // shows the sphere.
    let mut frame = |manager: &mut Manager, width: u32, t: f64| {
        let shows = manager.frame(&scene, &camera(width), t);
        let asked: Vec<_> = std::iter::from_fn(|| commands.try_recv().ok())
            .filter_map(|c| match c {
                Command::Request(r) if r.needed_in_ms.is_none() => Some(r),
                _ => None,
            })
            .collect();
        (asked, shows[sphere])
    };
    let (asked, _) = frame(&mut manager, 320, 0.0);
    // A request answered with the texture it asked for.
    let answer = |r: &relief_client::manager::TextureRequest| {
        let tracer = ObjectTracer::new(&scene.objects[sphere]);
        let texture = bake(&tracer, r.eye, r.size, r.depth_bits, r.projection).unwrap();
        arrive(
            &arrivals,
            r.id,
            ReadyTexture::new(texture, relief_render::impostor::Faces::Front),
        );
    };
    let first = asked.first().expect("a request for now").clone();
    answer(&first);
    let (asked, show) = frame(&mut manager, 320, 0.1);
    assert!(
        matches!(show, Show::Impostor { .. }) && asked.is_empty(),
        "{show:?} {asked:?}"
    );
    let texel = manager
        .describe(&scene, sphere, &show, &camera(320))
        .expect("described")
        .texel_pixels;
    // A screen on which the texel covers midway between refining and giving way.
    let wanted = 0.5 * (REFINE_TEXEL + COARSEST_SHOWN);
    let width = (320.0 * wanted / texel).round() as u32;
    let (asked, show) = frame(&mut manager, width, 0.2);
    let shown = manager
        .describe(&scene, sphere, &show, &camera(width))
        .expect("still shown");
    assert!(
        shown.texel_pixels > REFINE_TEXEL && shown.texel_pixels < COARSEST_SHOWN,
        "texel {} px",
        shown.texel_pixels
    );
    let finer = asked
        .first()
        .unwrap_or_else(|| panic!("no finer texture asked at {} px", shown.texel_pixels));
    assert!(
        finer.size > first.size,
        "asked {} after {}",
        finer.size,
        first.size
    );
    // Made from the same eye, the finer texture replaces the coarse one: it is shown,
    // and nothing more is asked for.
    answer(finer);
    let (asked, show) = frame(&mut manager, width, 0.3);
    let shown = manager
        .describe(&scene, sphere, &show, &camera(width))
        .expect("shown");
    assert!(
        shown.texel_pixels < REFINE_TEXEL,
        "texel {} px",
        shown.texel_pixels
    );
    assert!(asked.is_empty(), "{asked:?}");
}

#[test]
fn one_request_for_now_is_in_flight_per_object() {
    let scene = Scene::load("default").unwrap();
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    // Nobody answers: every frame finds the sphere without a texture.
    let (mut manager, mut commands) = unanswered(&scene, Config::default());
    let mut now_requests = 0;
    // Eyes 90° apart around the sphere: no request for one serves another.
    for (frame, angle) in [0f32, 90.0, 180.0, 270.0].into_iter().enumerate() {
        let drawn = (around(centre, angle.to_radians()), centre, frame as f64);
        now_requests +=
            requests_from_frame(&mut manager, &mut commands, &scene, drawn, "sphere", false).len();
    }
    assert_eq!(now_requests, 1);
}

/// A prediction not come by the time the eye is where it was made for is late: the
/// object, stale, asks for its texture as needed now (on a server that request joins
/// the prediction's job and moves it ahead of predicted work) instead of waiting on it
/// — at 64 load-test clients, waiting made most of the stalled frames. So does one
/// drawn as geometry in the stead of its texture meanwhile.
#[test]
fn a_stale_object_asks_now_though_a_late_prediction_covers_its_eye() {
    for config in [without_stand_ins(), Config::default()] {
        asks_now_though_a_late_prediction_covers_its_eye(config);
    }
}

fn asks_now_though_a_late_prediction_covers_its_eye(config: Config) {
    use relief_client::manager::Failure;

    let scene = Scene::load("default").unwrap();
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    let (mut manager, mut commands, arrivals) = wired(&scene, config.clone());
    // Orbit the sphere at 30°/s until a prediction for it goes out; nothing answers.
    let (mut now, mut predicted) = (Vec::new(), None);
    let mut t = 0.0;
    for frame in 0..30 {
        t = frame as f32 / 30.0;
        manager.frame(&scene, &camera_round(centre, 30.0 * t), t as f64);
        for command in std::iter::from_fn(|| commands.try_recv().ok()) {
            match command {
                Command::Request(r) if r.object == "sphere" && r.needed_in_ms.is_none() => now.push(r.id),
                Command::Request(r) if r.object == "sphere" => predicted = predicted.or(Some(r.eye)),
                _ => {}
            }
        }
        if predicted.is_some() {
            break;
        }
    }
    let predicted = predicted.expect("a prediction for the sphere");
    // The request for now (nothing was held) fails: only the prediction is out.
    assert_eq!(now.len(), 1);
    let failure = Failure::Refused("no worker".into());
    arrivals.send(Arrival::Failed { id: now[0], failure }).unwrap();
    // The eye reaches the predicted one with the prediction still out.
    let eye = scene.object("sphere").unwrap().to_world(predicted).as_vec3();
    let drawn = (eye, centre, f64::from(t) + 0.5);
    let asked = requests_from_frame(&mut manager, &mut commands, &scene, drawn, "sphere", false);
    assert_eq!(
        asked.len(),
        1,
        "the sphere waited on its late prediction ({config:?})"
    );
    assert!(asked[0].distance(eye) < 1e-3);
    let counters = &manager.counters;
    let standing_in = config.stand_in_triangles > 0;
    assert_eq!(counters.stand_ins > 0, standing_in, "{config:?}");
    assert_eq!(counters.stale_frames > 0, !standing_in, "{config:?}");
}

#[test]
fn the_local_generator_serves_requests_for_now_in_the_order_asked() {
    use relief_client::manager::{Arrival, TextureRequest};
    use relief_core::relief::{DepthBits, SourceProjection};
    let scene = Arc::new(Scene::load("default").unwrap());
    let (commands_tx, commands_rx) = unbounded_channel();
    let (arrivals_tx, mut arrivals_rx) = unbounded_channel();
    // All asked before the generator can have finished the first.
    let objects = ["sphere", "knot", "tree", "sphere"];
    for (id, object) in objects.iter().enumerate() {
        let request = TextureRequest {
            id: id as u64 + 1,
            object: object.to_string(),
            eye: Vec3::new(0.0, 2.0, 12.0),
            size: 32,
            depth_bits: DepthBits::Eight,
            projection: SourceProjection::Perspective,
            needed_in_ms: None,
            serve_within: 0.0,
        };
        commands_tx.send(Command::Request(request)).unwrap();
    }
    spawn_local(scene, commands_rx, arrivals_tx);
    let order: Vec<u64> = (0..objects.len())
        .map(
            |_| match arrivals_rx.blocking_recv().expect("the generator stopped") {
                Arrival::Texture { id, .. } => id,
                Arrival::Failed { id, failure } => panic!("request {id} failed: {failure}"),
                Arrival::ServerLoad { .. } | Arrival::LinkRoundTrip { .. } => {
                    panic!("the local generator has no link to report on")
                }
            },
        )
        .collect();
    assert_eq!(order, [1, 2, 3, 4]);
}

/// Textures are asked for in half-octave steps: edges at most 1.46× (texels 2.1×) what
/// the screen can show, within 32…1024.
#[test]
fn texture_edges_climb_in_half_octaves() {
    let ladder: Vec<u32> = [
        1, 32, 33, 48, 49, 64, 65, 100, 130, 200, 257, 361, 512, 513, 721, 5000,
    ]
    .into_iter()
    .map(texture_ladder)
    .collect();
    assert_eq!(
        ladder,
        [
            32, 32, 48, 48, 64, 64, 88, 128, 184, 256, 360, 512, 512, 720, 1024, 1024
        ]
    );
    for need in 32..=1024 {
        let edge = texture_ladder(need);
        assert!(
            edge >= need && edge as f32 <= 1.46 * need as f32,
            "{need} → {edge}"
        );
    }
}

/// Between two held textures of the sphere, far enough from both, the nearer is shown
/// and the other drawn behind it as its partner (it holds what the eye has turned to
/// see); near a texture's own eye, no partner is drawn.
#[test]
fn between_two_textures_the_other_is_drawn_behind() {
    let scene = Arc::new(Scene::load("default").unwrap());
    let mut manager = served_locally(&scene, Config::default());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let camera_at = |degrees: f32| camera_round(centre, degrees);
    for degrees in [0.0, 70.0] {
        assert!(
            manager.warm_up(&scene, &[camera_at(degrees)], Duration::from_secs(60)),
            "textures for {degrees}° did not arrive"
        );
    }
    let between = camera_at(40.0);
    let shows = manager.frame(&scene, &between, 0.0);
    let Show::Impostor {
        texture,
        partner: Some((partner, _)),
        ..
    } = shows[sphere]
    else {
        panic!("no partner at 40°: {:?}", shows[sphere]);
    };
    assert_ne!(texture, partner);
    let mut gbuffer = GBuffer::new(320, 180);
    manager.render(&scene, &shows, &between, &mut gbuffer);
    assert!(manager.counters.partners >= 1);
    let near = manager.frame(&scene, &camera_at(72.0), 0.1);
    assert!(
        matches!(near[sphere], Show::Impostor { partner: None, .. }),
        "2° from a texture's eye: {:?}",
        near[sphere]
    );
}

/// Stale object-frames are counted by cause: before any texture, `missing`; a sphere's
/// one texture 50° from the eye — within tolerance (a sphere's gaps do not grow) but
/// with no partner to fill the side it never saw — `too_far`.
#[test]
fn stale_object_frames_are_counted_by_cause() {
    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let camera_at = |degrees: f32| camera_round(centre, degrees);
    let config = Config {
        predict: false,
        ..without_stand_ins()
    };
    let (mut unserved, _commands) = unanswered(&scene, config.clone());
    unserved.frame(&scene, &camera_at(0.0), 0.0);
    let causes = unserved.counters.stale_causes;
    assert_eq!(
        (causes.missing, causes.beyond_tolerance, causes.too_far),
        (1, 0, 0)
    );

    let mut manager = served_locally(&scene, config);
    assert!(manager.warm_up(&scene, &[camera_at(0.0)], Duration::from_secs(60)));
    manager.frame(&scene, &camera_at(50.0), 0.0);
    let causes = manager.counters.stale_causes;
    assert_eq!(
        (causes.missing, causes.beyond_tolerance, causes.too_far),
        (0, 0, 1)
    );
    assert_eq!(manager.counters.stale_frames, 1);
}

/// A warm-up readies every view it is given, not the first alone: warmed up for the
/// sphere from 0° and 50° round it, neither frame is stale (warmed up for 0° alone, the
/// frame at 50° is: see `stale_object_frames_are_counted_by_cause`). With predictions
/// on, a second view from another eye, turned onto what the first does not see, is
/// readied too, and only the first view predicts (predicted from every view, the
/// second's predictions, made for the first's eye, were withdrawn by the first's frame
/// and asked again by its own: over a slow link, never all in).
#[test]
fn a_warm_up_readies_every_view_it_is_given() {
    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    let camera_at = |degrees: f32| camera_round(centre, degrees);
    let config = Config {
        predict: false,
        ..Config::default()
    };
    let mut manager = served_locally(&scene, config);
    assert!(manager.warm_up(
        &scene,
        &[camera_at(0.0), camera_at(50.0)],
        Duration::from_secs(60)
    ));
    manager.frame(&scene, &camera_at(50.0), 0.0);
    manager.frame(&scene, &camera_at(0.0), 0.1);
    assert_eq!(manager.counters.stale_frames, 0);

    let scene = Arc::new(Scene::load("default").unwrap());
    // Between the sphere and the knot, looking at one, then from 1.5 m on at the other.
    let view = |eye: Vec3, at: Vec3| Camera::look_at(eye, at, Vec3::Y, 60.0, 160, 90).unwrap();
    let sphere = view(Vec3::new(0.0, 2.0, 0.5), Vec3::new(-3.0, 1.0, 0.0));
    let knot = view(Vec3::new(0.0, 2.0, 2.0), Vec3::new(3.0, 1.3, 0.0));
    let mut manager = served_locally(&scene, Config::default());
    assert!(manager.warm_up(&scene, &[sphere, knot], Duration::from_secs(30)));
    manager.frame(&scene, &knot, 0.0);
    manager.frame(&scene, &sphere, 0.1);
    assert_eq!(manager.counters.stale_frames, 0);
    // Nothing is predicted from the second view: unanswered, the warm-up asks for the
    // knot only as needed now.
    let (mut manager, mut commands) = unanswered(&scene, Config::default());
    assert!(!manager.warm_up(&scene, &[sphere, knot], Duration::from_millis(200)));
    let mut knot_asked = (0, 0);
    while let Ok(command) = commands.try_recv() {
        if let Command::Request(r) = command
            && r.object == "knot"
        {
            match r.needed_in_ms {
                Some(_) => knot_asked.1 += 1,
                None => knot_asked.0 += 1,
            }
        }
    }
    assert_eq!(knot_asked, (1, 0), "(now, predicted)");
}

/// An object without a valid texture is drawn exactly as geometry, nearest first, each
/// that still fits in the frame's [`STAND_IN_TRIANGLES`]: of a rock of 1.5 M triangles
/// and two of 0.6 M beyond it, holding nothing yet, the near one fits and neither far
/// one does after it (farthest first, both far ones would have), so they count as
/// stale; each asks for its first texture once. And a tree turned past its texture's
/// valid angle is drawn as geometry, not stale, while its texture for the eye is asked
/// for.
///
/// [`STAND_IN_TRIANGLES`]: relief_client::manager::policy::STAND_IN_TRIANGLES
#[test]
fn stale_objects_stand_in_as_geometry_nearest_first_within_the_frames_triangles() {
    use relief_client::manager::policy::STAND_IN_TRIANGLES;

    let text = r#"
        [[objects]]
        name = "boulder"
        generator = { kind = "rock", resolution = 354, seed = 11 }
        translate = [0, 0, -4]

        [[objects]]
        name = "stone"
        generator = { kind = "rock", resolution = 224, seed = 12 }
        instances = [{ translate = [1, 0, -9] }, { translate = [-1, 0, -10] }]
        "#;
    let scene = Arc::new(Scene::parse(text).unwrap());
    let triangles = |name| scene.objects[index(&scene, name)].mesh.triangle_count();
    let (boulder, stone) = (triangles("boulder"), triangles("stone.1"));
    // (The premise: the boulder fits, and then no stone; the two stones would.)
    assert!(boulder <= STAND_IN_TRIANGLES && boulder + stone > STAND_IN_TRIANGLES);
    assert!(2 * stone <= STAND_IN_TRIANGLES);
    let config = Config {
        predict: false,
        ..Config::default()
    };
    let (mut waiting, mut commands) = unanswered(&scene, config.clone());
    let camera = Camera::look_at(
        Vec3::new(0.0, 1.0, 2.0),
        Vec3::new(0.0, 0.5, -8.0),
        Vec3::Y,
        60.0,
        640,
        360,
    )
    .unwrap();
    for _ in 0..3 {
        let shows = waiting.frame(&scene, &camera, 0.0);
        assert!(shows.iter().all(|s| matches!(s, Show::Geometry)), "{shows:?}");
    }
    let counters = &waiting.counters;
    assert_eq!(
        (
            counters.stand_ins,
            counters.stale_frames,
            counters.stale_causes.missing
        ),
        (3, 3, 6),
        "(object-frames drawn as geometry instead, stale frames, stale object-frames)"
    );
    let mut asked: Vec<String> = std::iter::from_fn(|| commands.try_recv().ok())
        .filter_map(|c| match c {
            Command::Request(r) => Some(r.object),
            _ => None,
        })
        .collect();
    asked.sort();
    assert_eq!(
        asked,
        ["boulder", "stone.1", "stone.2"],
        "one request each for its first texture"
    );

    // Turned past its texture's valid angle.
    let tree_scene = Arc::new(
        Scene::parse(
            r#"
        [[objects]]
        name = "tree"
        generator = { kind = "tree", seed = 7, depth = 5, leaves = 10 }
        "#,
        )
        .unwrap(),
    );
    let centre = tree_scene.objects[0].world_bounds().center();
    let camera_at = |degrees: f32| {
        let angle = degrees.to_radians();
        let eye = centre + 16.0 * Vec3::new(angle.cos(), 0.2, angle.sin());
        Camera::look_at(eye, centre, Vec3::Y, 60.0, 640, 360).unwrap()
    };
    let mut manager = served_locally(&tree_scene, config);
    assert!(manager.warm_up(&tree_scene, &[camera_at(0.0)], Duration::from_secs(60)));
    let shows = manager.frame(&tree_scene, &camera_at(15.0), 0.0);
    assert!(matches!(shows[0], Show::Geometry), "{:?}", shows[0]);
    let counters = &manager.counters;
    assert_eq!(
        (counters.stand_ins, counters.stale_frames, counters.requests_now),
        (1, 0, 1),
        "(drawn as geometry instead, stale frames, asked for now)"
    );
}

/// A texture shown alone goes stale once the band past its rim that it cannot show
/// ([`LONE_BAND`] pixels, predicted from the rim's curvature) would open: for a sphere
/// of radius `R` pixels, at `acos(1 − LONE_BAND/R)` round it. A sphere small on screen,
/// whose band opens late, goes stale at its lone turn instead ([`LONE_MAX_TURN`]: its
/// turned rim shows ragged before the band opens).
#[test]
fn a_lone_texture_goes_stale_when_its_rim_band_opens_or_past_its_turn() {
    use relief_client::manager::policy::{LONE_BAND, LONE_MAX_TURN};

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let config = Config {
        predict: false,
        ..without_stand_ins()
    };
    // Turned round the sphere a degree at a time, seen at `width × height`: where it
    // first goes stale, and where the band predicts.
    let stale_from = |width: u32, height: u32| {
        let camera = |degrees: f32| {
            Camera::look_at(
                around(centre, degrees.to_radians()),
                centre,
                Vec3::Y,
                60.0,
                width,
                height,
            )
            .unwrap()
        };
        let mut manager = served_locally(&scene, config.clone());
        let first = camera(0.0);
        assert!(manager.warm_up(&scene, &[first], Duration::from_secs(60)));
        let radius_px = scene.objects[sphere].world_bounds().extent().x * 0.5 * first.focal_pixels()
            / first.eye.as_vec3().distance(centre);
        let band_opens = (1.0 - LONE_BAND / radius_px).acos().to_degrees();
        let stale = (1..40)
            .map(|degrees| degrees as f32)
            .find(|&degrees| {
                manager.frame(&scene, &camera(degrees), 0.0);
                manager.counters.stale_frames > 0
            })
            .expect("stale before 40°");
        assert_eq!(manager.counters.stale_causes.too_far, 1);
        eprintln!("sphere of {radius_px:.0} px: stale from {stale}°, band predicts {band_opens:.1}°");
        (stale, band_opens)
    };
    let lone_turn = LONE_MAX_TURN.to_degrees();
    // Large (and still dearer drawn than warped): the band opens first.
    let (stale, band_opens) = stale_from(1280, 720);
    assert!(
        (stale - band_opens).abs() <= 2.0 && stale < lone_turn - 2.0,
        "stale from {stale}°, where a {LONE_BAND} px band opens at {band_opens:.1}°"
    );
    // Small: the turn comes first.
    let (stale, band_opens) = stale_from(320, 180);
    assert!(
        band_opens > lone_turn + 3.0 && (lone_turn..=lone_turn + 2.0).contains(&stale),
        "stale from {stale}°, the lone turn {lone_turn}°, the band at {band_opens:.1}°"
    );
}

/// A cube of `cells`² quads a face (two triangles each), side 2, centred on the
/// origin, wound counter-clockwise seen from outside: as an OBJ file's text.
fn cube_obj(cells: usize) -> String {
    let mut text = String::new();
    let mut vertices = 0;
    // Each face: its normal's axis and sign, and the two axes across it (u × v = normal).
    for (axis, sign) in [(0, 1.0f32), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0)] {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let at = |i: usize, j: usize| {
            let mut p = [0.0f32; 3];
            p[axis] = sign;
            // (On the negative face, v runs the other way: the winding stays outward.)
            p[u] = -1.0 + 2.0 * i as f32 / cells as f32;
            p[v] = sign * (-1.0 + 2.0 * j as f32 / cells as f32);
            p
        };
        for j in 0..=cells {
            for i in 0..=cells {
                let [x, y, z] = at(i, j);
                text += &format!("v {x} {y} {z}\n");
            }
        }
        let index = |i: usize, j: usize| vertices + j * (cells + 1) + i + 1;
        for j in 0..cells {
            for i in 0..cells {
                let (a, b, c, d) = (index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1));
                text += &format!("f {a} {b} {c} {d}\n");
            }
        }
        vertices += (cells + 1) * (cells + 1);
    }
    text
}

/// Past a sharp edge a flat face comes into view at once: a cube's texture made with
/// two of its faces edge-on goes stale alone within a degree of the turn where
/// [`LONE_UNSEEN`] of what the eye sees is that face (the eye past the face's plane),
/// where its outline, all sharp edges, leaves no band past its rim and the turn alone
/// would allow [`LONE_MAX_TURN`].
#[test]
fn a_lone_texture_goes_stale_when_a_flat_face_turns_into_view() {
    use relief_client::manager::policy::{LONE_MAX_TURN, LONE_UNSEEN};

    let dir = relief_core::scratch::PrivateDir::new("relief-cube").unwrap();
    let path = dir.join("cube.obj");
    // (Triangles enough that a texture costs less than drawing them.)
    std::fs::write(&path, cube_obj(24)).unwrap();
    let scene = Arc::new(Scene::load(path.to_str().unwrap()).unwrap());
    let cube = index(&scene, "cube");
    let centre = scene.objects[cube].world_bounds().center();
    let config = Config {
        predict: false,
        ..without_stand_ins()
    };
    let mut manager = served_locally(&scene, config);
    // From +x, a little above the middle: the faces ±z edge-on.
    let first = camera_round(centre, 0.0);
    assert!(manager.warm_up(&scene, &[first], Duration::from_secs(60)));
    assert!(
        matches!(manager.frame(&scene, &first, 0.0)[cube], Show::Impostor { .. }),
        "the cube is drawn from a texture at its own eye"
    );
    // Turned towards +z a degree at a time: the face +z comes into view once the eye,
    // 6 m out, passes its plane (9.6°), each face seen along the line to its centre.
    let stale = (1..20)
        .map(|degrees| degrees as f32)
        .find(|&degrees| {
            manager.frame(&scene, &camera_round(centre, degrees), 0.0);
            manager.counters.stale_frames > 0
        })
        .expect("stale before 20°");
    assert_eq!(manager.counters.stale_causes.too_far, 1);
    // (Faces of the same area, centred on their normals; the top and the bottom, above
    // and below the eye, are not seen.)
    let share = |degrees: f32| {
        let eye = around(centre, degrees.to_radians()) - centre;
        let seen = |face: Vec3| (-face.dot((face - eye).normalize())).max(0.0);
        let (front, side) = (seen(Vec3::X), seen(Vec3::Z));
        side / (front + side)
    };
    assert!(
        share(stale) > LONE_UNSEEN && share(stale - 1.0) <= LONE_UNSEEN,
        "stale from {stale}°, the face's share then {:.3}",
        share(stale)
    );
    assert!(stale < LONE_MAX_TURN.to_degrees() - 2.0, "stale from {stale}°");
}

/// A solid's orthographic texture is shown alone [`LONE_MAX_TURN`] round at the
/// default tolerance, its perspective one [`PERSPECTIVE_LONE_TURN`]; one of leaves or
/// sheets (an open mesh: the ground's plane here) up to [`LONE_TURN_CAP`], either way.
///
/// [`LONE_TURN_CAP`]: relief_client::manager::policy::LONE_TURN_CAP
/// [`PERSPECTIVE_LONE_TURN`]: relief_client::manager::policy::PERSPECTIVE_LONE_TURN
#[test]
fn a_solid_is_shown_alone_less_far_round_than_a_sheet() {
    use relief_client::manager::policy::{
        LONE_MAX_TURN, LONE_TURN_CAP, PERSPECTIVE_LONE_TURN, lone_max_turn,
    };
    use relief_core::relief::SourceProjection;

    let scene = Scene::load("orbit-sphere").unwrap();
    let turn = |name: &str, projection| lone_max_turn(&scene.objects[index(&scene, name)], projection);
    let (orthographic, perspective) = (SourceProjection::Orthographic, SourceProjection::Perspective);
    assert_eq!(turn("sphere", orthographic), LONE_MAX_TURN);
    assert_eq!(turn("sphere", perspective), PERSPECTIVE_LONE_TURN);
    assert_eq!(turn("ground", orthographic), LONE_TURN_CAP);
    assert_eq!(turn("ground", perspective), LONE_TURN_CAP);
}

/// Orthographic textures that fall short of what their own eye sees switch their
/// object's requests to perspective ([`OWN_EYE_GROWTH`], two of the last three:
/// [`SHORT_NEEDED`]): the scanned bunny seen near, from the front and from behind (its
/// default path's frames 9 and 84), whose ears' undersides the eye's rays meet and
/// parallel ones pass by. The frame that takes in the second lets go of both and asks
/// again from its eye, in perspective. The sphere's textures, seen as near on its
/// scene's own orbit (a third of it apart), show what their eye sees: its requests stay
/// orthographic, and once the second is taken in none is asked for. (Fails with the
/// switch left out, made for every solid, or made on one texture.)
///
/// [`OWN_EYE_GROWTH`]: relief_client::manager::policy::OWN_EYE_GROWTH
/// [`SHORT_NEEDED`]: relief_client::manager::policy::SHORT_NEEDED
#[test]
fn an_object_whose_parallel_rays_fall_short_is_asked_in_perspective() {
    use relief_core::camera::CameraPath;
    use relief_core::relief::SourceProjection;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let bunny = shared_bunny();
    // The projections of the requests for now made from each of `frames` of `path` in
    // turn, each answered before the next, and of the one (if any) that the frame taking
    // in the last answer makes.
    let asked_in = |scene: Scene, object: usize, path: CameraPath, frames: [u32; 2]| {
        let scene = Arc::new(scene);
        let config = Config {
            predict: false,
            ..Config::default()
        };
        let (mut manager, mut commands, arrivals) = wired(&scene, config);
        let name = scene.objects[object].name.clone();
        let tracer = ObjectTracer::new(&scene.objects[object]);
        let mut asked_after = None;
        let asked = frames.map(|frame| {
            let camera = path
                .pose(frame)
                .unwrap()
                .camera(scene.fov_y_degrees, 640, 360)
                .unwrap();
            manager.frame(&scene, &camera, frame as f64);
            let r = request_now(&mut commands);
            assert_eq!(r.object, name);
            let texture = bake(&tracer, r.eye, r.size, r.depth_bits, r.projection).unwrap();
            arrive(
                &arrivals,
                r.id,
                ReadyTexture::new(texture, relief_render::impostor::Faces::Front),
            );
            manager.frame(&scene, &camera, frame as f64 + 0.5);
            asked_after = std::iter::from_fn(|| commands.try_recv().ok()).find_map(|c| match c {
                Command::Request(r) if r.needed_in_ms.is_none() => Some((r.projection, r.eye)),
                _ => None,
            });
            (r.projection, r.eye)
        });
        let projections = asked.map(|(projection, _)| projection);
        // (From the same eye.)
        let again = asked_after.map(|(projection, eye)| {
            assert!(
                eye.distance(asked[1].1) < 1e-3 * eye.length(),
                "{eye} {}",
                asked[1].1
            );
            projection
        });
        (projections, again)
    };
    let (orthographic, perspective) = (SourceProjection::Orthographic, SourceProjection::Perspective);
    let bunny = Scene::load(bunny.to_str().unwrap()).unwrap();
    let path = bunny.default_path();
    assert_eq!(
        asked_in(bunny, 0, path, [9, 84]),
        ([orthographic; 2], Some(perspective))
    );
    // (A third of its orbit apart: the first does not cover the second.)
    let spheres = Scene::load("orbit-sphere").unwrap();
    let (sphere, path) = (index(&spheres, "sphere"), spheres.path.clone());
    assert_eq!(
        asked_in(spheres, sphere, path, [0, 80]),
        ([orthographic; 2], None)
    );
}

/// The scanned bunny's flight warm-up ends with its first views' textures all in.
/// One of them is orthographic and falls short past the tolerance at its own eye: it
/// cannot be shown even there, and the same texture comes whenever it is asked for
/// again from that still eye, falling short again each time. (Had that not counted
/// towards the switch to perspective, the warm-up asked for it again and again and gave
/// up at its limit, [`WARM_UP_LIMIT`].)
///
/// [`WARM_UP_LIMIT`]: relief_client::flight::WARM_UP_LIMIT
#[test]
fn the_bunny_warm_up_ends() {
    use relief_client::flight::Flight;

    let scene = Arc::new(Scene::load(shared_bunny().to_str().unwrap()).unwrap());
    let mut manager = served_locally(&scene, Config::default());
    let flight = Flight {
        scene: &scene,
        size: (640, 360),
        fps: 30,
        frames: scene.path.frame_count(),
        start: 0,
        wrap: false,
    };
    assert!(flight.warm_up(&mut manager).unwrap());
}

/// An orthographic texture that falls short at its own eye, received again, counts
/// again towards asking its object's textures in perspective — but only when asked for
/// again since it came, not when one bake answers two requests at once (a server
/// merges a request for now into a prediction's job). The scanned bunny seen from its
/// path's frame 9 (as in `an_object_whose_parallel_rays_fall_short_is_asked_in_perspective`),
/// at a tolerance of [`OWN_EYE_GROWTH`], so that the texture cannot be shown even at
/// its own eye. (Fails with every texture received again counted, or none.)
///
/// [`OWN_EYE_GROWTH`]: relief_client::manager::policy::OWN_EYE_GROWTH
#[test]
fn a_short_texture_received_again_counts_again() {
    use relief_client::manager::policy::OWN_EYE_GROWTH;
    use relief_core::relief::SourceProjection;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let scene = Scene::load(shared_bunny().to_str().unwrap()).unwrap();
    let config = Config {
        tolerance: OWN_EYE_GROWTH,
        ..Config::default()
    };
    let (mut manager, mut commands, arrivals) = wired(&scene, config);
    let camera = |frame: u32| {
        (scene.default_path().pose(frame).unwrap())
            .camera(scene.fov_y_degrees, 640, 360)
            .unwrap()
    };
    let mut requests = |manager: &mut Manager, frame: u32, t: f64| {
        manager.frame(&scene, &camera(frame), t);
        std::iter::from_fn(|| commands.try_recv().ok())
            .filter_map(|c| match c {
                Command::Request(r) => Some(r),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
    let now = |asked: Vec<TextureRequest>| asked.into_iter().find(|r| r.needed_in_ms.is_none());
    // Asked for now from frame 9's eye; flown on unanswered until a prediction is out
    // too (one request for now at a time).
    let first = now(requests(&mut manager, 9, 0.0)).expect("a request for now");
    assert_eq!(first.projection, SourceProjection::Orthographic);
    let predicted = (10..40)
        .find_map(|frame| {
            let asked = requests(&mut manager, frame, f64::from(frame - 9) / 30.0);
            asked.into_iter().find(|r| r.needed_in_ms.is_some())
        })
        .expect("a prediction");
    let tracer = ObjectTracer::new(&scene.objects[0]);
    let texture = bake(&tracer, first.eye, first.size, first.depth_bits, first.projection).unwrap();
    let ready = ReadyTexture::new(texture, relief_render::impostor::Faces::Front);
    // One bake answers both: received once. Back at frame 9's eye, still, it asks again.
    arrive(&arrivals, first.id, ready.clone());
    arrive(&arrivals, predicted.id, ready.clone());
    let again = now(requests(&mut manager, 9, 2.0)).expect("asked again");
    assert_eq!(again.projection, SourceProjection::Orthographic);
    assert!(again.eye.distance(first.eye) < 1e-3 * first.eye.length());
    // The same comes: received twice, and the frame that takes it in asks from the same
    // eye in perspective.
    arrive(&arrivals, again.id, ready);
    let after = now(requests(&mut manager, 9, 2.1)).expect("asked in perspective");
    assert_eq!(after.projection, SourceProjection::Perspective);
    assert!(after.eye.distance(first.eye) < 1e-3 * first.eye.length());
}

/// An object wholly off screen is not needed now: no stale frame, no request for now;
/// a prediction only where a view turned by up to [`PREDICTED_VIEW_MARGIN`] would show
/// it, withdrawn once it would not. Turned towards, it is needed and asked for.
///
/// [`PREDICTED_VIEW_MARGIN`]: relief_client::manager::policy::PREDICTED_VIEW_MARGIN
#[test]
fn an_object_off_screen_is_not_needed_now() {
    use relief_client::manager::policy::PREDICTED_VIEW_MARGIN;

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let eye = around(centre, 0.0);
    let config = Config {
        predict: false,
        ..Config::default()
    };
    let (mut manager, mut commands) = unanswered(&scene, config);
    // Looking straight away from it.
    let away = (eye, eye + (eye - centre), 0.0);
    let now = requests_from_frame(&mut manager, &mut commands, &scene, away, "sphere", false);
    assert!(now.is_empty(), "{now:?}");
    assert_eq!((manager.counters.needs, manager.counters.stale_frames), (0, 0));
    // With prediction on, nothing is asked for it either: the view would have to turn
    // by far more than `PREDICTED_VIEW_MARGIN` to show it.
    let (mut predicting, mut predictions) = unanswered(&scene, Config::default());
    let ahead = requests_from_frame(&mut predicting, &mut predictions, &scene, away, "sphere", true);
    assert!(ahead.is_empty(), "{ahead:?}");
    // Turned so that it lies off the screen's side, its texture for where the eye is
    // going is asked for while a turn of that margin would bring some of its box on
    // screen, and not past it: the view reaches `half_x` across (320×180, 60° high),
    // the box's corners lie within `radius` of its centre's direction across. (By a
    // view widened only upwards and downwards, to the same shape, 72° across: not
    // within the margin.)
    let half_x = (30f32.to_radians().tan() * 16.0 / 9.0).atan();
    let reach = half_x + PREDICTED_VIEW_MARGIN;
    let bounds = scene.objects[sphere].world_bounds();
    let extent = bounds.extent();
    let radius = (0.5 * extent.x.hypot(extent.z) / eye.distance(centre)).asin();
    let off_by = |angle: f32| eye + glam::Quat::from_rotation_y(angle) * (centre - eye);
    let asked_off_by = |angle: f32| {
        let (mut predicting, mut predictions) = unanswered(&scene, Config::default());
        let view = (eye, off_by(angle), 0.0);
        let asked = requests_from_frame(&mut predicting, &mut predictions, &scene, view, "sphere", true);
        assert_eq!(predicting.counters.needs, 0);
        !asked.is_empty()
    };
    let degree = 1f32.to_radians();
    assert!(asked_off_by(half_x + radius + degree), "just off the screen");
    assert!(asked_off_by(reach + radius - 3.0 * degree), "within the margin");
    assert!(!asked_off_by(reach + radius + 3.0 * degree), "past the margin");
    // A prediction asked for is withdrawn once the view turns away for good.
    let (mut predicting, mut predictions) = unanswered(&scene, Config::default());
    let beside = (eye, off_by(reach + radius - 3.0 * degree), 0.0);
    assert!(
        !requests_from_frame(&mut predicting, &mut predictions, &scene, beside, "sphere", true).is_empty()
    );
    let away = Camera::look_at(eye, eye + (eye - centre), Vec3::Y, 60.0, 320, 180).unwrap();
    predicting.frame(&scene, &away, 0.1);
    let withdrawn = std::iter::from_fn(|| predictions.try_recv().ok())
        .any(|c| matches!(c, Command::Withdraw(ids) if !ids.is_empty()));
    assert!(withdrawn && predicting.requests_open() == 0);
    // Turned towards it: needed, drawn as geometry without a texture, asked for now.
    let towards = (eye, centre, 0.2);
    let now = requests_from_frame(&mut manager, &mut commands, &scene, towards, "sphere", false);
    assert_eq!(now.len(), 1);
    let counters = &manager.counters;
    assert_eq!(
        (counters.needs, counters.stand_ins, counters.stale_frames),
        (1, 1, 0)
    );
}

/// While warming up, an object just off the screen's side is asked for ahead, needed no
/// sooner than the warm-up may last: a server busy with the cold start does not refuse
/// it as late, and the flight does not set off without it. Out of time, the warm-up
/// withdraws it, and the flight asks afresh, a round trip ahead.
#[test]
fn warm_up_predictions_are_needed_when_the_flight_starts() {
    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let sphere = index(&scene, "sphere");
    let bounds = scene.objects[sphere].world_bounds();
    let centre = bounds.center();
    let eye = around(centre, 0.0);
    let half_x = (30f32.to_radians().tan() * 16.0 / 9.0).atan();
    let extent = bounds.extent();
    let radius = (0.5 * extent.x.hypot(extent.z) / eye.distance(centre)).asin();
    let aside = eye + glam::Quat::from_rotation_y(half_x + radius + 5f32.to_radians()) * (centre - eye);
    let camera = Camera::look_at(eye, aside, Vec3::Y, 60.0, 320, 180).unwrap();
    let (mut manager, mut commands) = unanswered(&scene, Config::default());
    let limit = Duration::from_secs(1);
    // (Nobody answers: it waits out the limit.)
    assert!(!manager.warm_up(&scene, &[camera], limit));
    let mut needed = Vec::new();
    let mut withdrawn = Vec::new();
    while let Ok(command) = commands.try_recv() {
        match command {
            Command::Request(r) if r.object == "sphere" => needed.push((r.id, r.needed_in_ms)),
            Command::Withdraw(ids) => withdrawn.extend(ids),
            _ => {}
        }
    }
    // (A round trip ahead, as in flight, it would be needed in about 240 ms.)
    assert!(!needed.is_empty(), "nothing asked ahead");
    assert!(needed.iter().all(|&(_, ms)| ms >= Some(800)), "{needed:?}");
    // Come after the flight started, its round trip of seconds would be planned for:
    // the warm-up, out of time, withdraws it, and the flight asks afresh, needed a
    // round trip ahead.
    assert!(
        needed.iter().all(|(id, _)| withdrawn.contains(id)),
        "{needed:?} {withdrawn:?}"
    );
    manager.frame(&scene, &camera, 0.0);
    let again: Vec<Option<u64>> = std::iter::from_fn(|| commands.try_recv().ok())
        .filter_map(|c| match c {
            Command::Request(r) if r.object == "sphere" => Some(r.needed_in_ms),
            _ => None,
        })
        .collect();
    assert!(
        !again.is_empty() && again.iter().all(|&ms| ms < Some(300)),
        "{again:?}"
    );
}

/// Latency is counted to a texture's arrival, and the pick-up from there to the frame
/// that takes it in; a texture's lifetime runs from its arrival to the last frame that
/// shows it. Known sleeps between request, arrival, take-in and the frames that show it
/// (or not) give known bounds on each figure.
#[test]
fn latency_pickup_and_lifetime_are_counted_from_arrival() {
    use relief_core::relief::DepthBits;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let (mut manager, mut commands, arrivals) = wired(&scene, without_stand_ins());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let eye = centre + Vec3::new(0.0, 1.0, 4.5);
    let camera = Camera::look_at(eye, centre, Vec3::Y, 60.0, 160, 90).unwrap();
    // Made before the request, so that the wait below is all the latency.
    let texture = bake(
        &ObjectTracer::new(&scene.objects[sphere]),
        eye,
        64,
        DepthBits::Eight,
        relief_core::relief::SourceProjection::Perspective,
    )
    .unwrap();
    manager.frame(&scene, &camera, 0.0);
    // The request for now the first frame made, answered by hand.
    let request = request_now(&mut commands);
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let (to_arrival, to_pickup, shown_for) = (
        Duration::from_millis(60),
        Duration::from_millis(40),
        Duration::from_millis(80),
    );
    std::thread::sleep(to_arrival);
    let ready = ReadyTexture::new(texture, relief_render::impostor::Faces::Front);
    std::thread::sleep(to_pickup);
    arrive(&arrivals, request.id, ready);
    let shows = manager.frame(&scene, &camera, 0.1);
    assert!(matches!(shows[sphere], Show::Impostor { .. }), "{shows:?}");
    let latency = manager.counters.latencies_ms[0];
    let pickup = manager.counters.pickup_ms[0];
    assert!(latency >= ms(to_arrival), "latency {latency} ms");
    assert!(pickup >= ms(to_pickup), "pickup {pickup} ms");
    // (Counted apart: the latency leaves the pick-up out.)
    assert!(latency < ms(to_arrival + to_pickup) - 5.0, "latency {latency} ms");
    // A request for now: among those needed now, and no prediction's lateness.
    assert_eq!(manager.counters.latencies_now_ms, vec![latency]);
    assert!(manager.counters.prediction_lateness_ms.is_empty());
    // Shown again after a while, then not (the eye too near: geometry).
    std::thread::sleep(shown_for);
    manager.frame(&scene, &camera, 0.2);
    let near = Camera::look_at(centre + Vec3::new(0.0, 0.0, 1.1), centre, Vec3::Y, 60.0, 160, 90).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(manager.frame(&scene, &near, 0.3)[sphere], Show::Geometry);
    let lifetimes = manager.texture_lifetimes();
    assert_eq!(
        (lifetimes.seconds.len(), lifetimes.never_shown),
        (1, 0),
        "{lifetimes:?}"
    );
    let lifetime = lifetimes.seconds[0] * 1e3;
    // From arrival to the last frame that showed it: the pick-up and the wait after,
    // not the last 300 ms.
    assert!(
        lifetime >= ms(to_pickup + shown_for) && lifetime < ms(to_pickup + shown_for) + 250.0,
        "lifetime {lifetime} ms"
    );
}

/// A texture never shown counts as superseded when its object was shown from another
/// of its textures after a frame took it in, and not when the object was not shown
/// again (here: drawn as geometry, the eye too near).
#[test]
fn never_shown_textures_count_whether_their_object_was_shown_after() {
    use relief_core::relief::{DepthBits, SourceProjection};
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let (mut manager, mut commands, arrivals) = wired(&scene, without_stand_ins());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let tracer = ObjectTracer::new(&scene.objects[sphere]);
    let camera_at = |eye: Vec3| Camera::look_at(eye, centre, Vec3::Y, 60.0, 160, 90).unwrap();
    // A frame's request for now, and its texture from that frame's eye, received now
    // (to be handed over by `arrive`).
    let mut ask_now = |manager: &mut Manager, t: f64, eye: Vec3| {
        manager.frame(&scene, &camera_at(eye), t);
        let request = request_now(&mut commands);
        let texture = bake(&tracer, eye, 64, DepthBits::Eight, SourceProjection::Perspective).unwrap();
        (
            request.id,
            ReadyTexture::new(texture, relief_render::impostor::Faces::Front),
        )
    };
    let front = centre + Vec3::new(0.0, 1.0, 4.5);
    let side = centre + Vec3::new(4.5, 1.0, 0.0);
    let back = centre + Vec3::new(0.0, 1.0, -4.5);
    let (id, ready) = ask_now(&mut manager, 0.0, front);
    arrive(&arrivals, id, ready);
    assert!(matches!(
        manager.frame(&scene, &camera_at(front), 0.1)[sphere],
        Show::Impostor { .. }
    ));
    // The side's texture comes, but the eye is back in front: shown from the front's.
    let (id, ready) = ask_now(&mut manager, 0.2, side);
    arrive(&arrivals, id, ready);
    assert!(matches!(
        manager.frame(&scene, &camera_at(front), 0.3)[sphere],
        Show::Impostor { .. }
    ));
    // The back's is received while a frame still shows the front's, but taken in only
    // by the next, from where the sphere is drawn as geometry: it never had a chance.
    let (id, ready) = ask_now(&mut manager, 0.4, back);
    assert!(matches!(
        manager.frame(&scene, &camera_at(front), 0.45)[sphere],
        Show::Impostor { .. }
    ));
    arrive(&arrivals, id, ready);
    let near = Camera::look_at(centre + Vec3::new(0.0, 0.0, 1.1), centre, Vec3::Y, 60.0, 160, 90).unwrap();
    assert_eq!(manager.frame(&scene, &near, 0.5)[sphere], Show::Geometry);
    let lifetimes = manager.texture_lifetimes();
    assert_eq!(
        (
            lifetimes.seconds.len(),
            lifetimes.never_shown,
            lifetimes.superseded
        ),
        (1, 2, 1),
        "{lifetimes:?}"
    );
}

/// A request that ends without its texture is counted by how it ended — refused, or
/// timed out — and is open no more; the end of one the manager did not ask for (or
/// already heard the end of) counts nothing. Needed still, it is asked for again.
#[test]
fn failed_requests_are_counted_by_how_they_ended() {
    use relief_client::manager::{Arrival, Failure};

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let (mut manager, mut commands, arrivals) = wired(&scene, Config::default());
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    let mut asked_now = |manager: &mut Manager, t: f64| {
        let drawn = (centre + Vec3::new(0.0, 1.0, 4.5), centre, t);
        manager.frame(
            &scene,
            &Camera::look_at(drawn.0, centre, Vec3::Y, 60.0, 160, 90).unwrap(),
            t,
        );
        std::iter::from_fn(|| commands.try_recv().ok())
            .filter_map(|c| match c {
                Command::Request(r) if r.needed_in_ms.is_none() => Some(r.id),
                _ => None,
            })
            .collect::<Vec<u64>>()
    };
    let first = asked_now(&mut manager, 0.0);
    assert_eq!(first.len(), 1);
    assert_eq!(manager.requests_open(), 1);
    let fail = |id, failure| arrivals.send(Arrival::Failed { id, failure }).unwrap();
    fail(first[0], Failure::TimedOut(Duration::from_secs(10)));
    fail(first[0], Failure::Refused("again".into()));
    fail(9999, Failure::Refused("not asked".into()));
    let again = asked_now(&mut manager, 0.1);
    let counters = &manager.counters;
    assert_eq!((counters.requests_timed_out, counters.requests_failed), (1, 0));
    assert_eq!(again.len(), 1, "asked for again");
    fail(again[0], Failure::Refused("no".into()));
    asked_now(&mut manager, 0.2);
    assert_eq!(manager.counters.requests_failed, 1);
}

/// A server that reports a long wait for new jobs makes the client's textures live
/// longer — its tolerance raised a step per report, up to `MAX_LOAD_SCALE` times the
/// user's — and one with room again brings it back, a smaller step per report, to the
/// user's. Reports taken in by one frame are one report.
#[test]
fn a_saturated_server_lengthens_the_textures_lives() {
    use relief_client::manager::policy::{
        LOAD_HIGH_WAIT, LOAD_LOW_WAIT, LOAD_STEP_DOWN, LOAD_STEP_UP, MAX_LOAD_SCALE,
    };

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let config = Config::default();
    let asked = config.tolerance;
    let (mut manager, _commands, arrivals) = wired(&scene, config);
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    let report = |manager: &mut Manager, wait: Duration| {
        arrivals.send(Arrival::ServerLoad { wait }).unwrap();
        manager.frame(&scene, &camera_round(centre, 0.0), 0.0);
        manager.tolerance() / asked
    };
    let busy = LOAD_HIGH_WAIT + Duration::from_millis(1);
    assert_eq!(report(&mut manager, busy), LOAD_STEP_UP);
    assert_eq!(report(&mut manager, busy), LOAD_STEP_UP * LOAD_STEP_UP);
    for _ in 0..20 {
        report(&mut manager, busy);
    }
    assert_eq!(manager.tolerance() / asked, MAX_LOAD_SCALE);
    // Between the two bounds it stays.
    assert_eq!(
        report(&mut manager, (LOAD_HIGH_WAIT + LOAD_LOW_WAIT) / 2),
        MAX_LOAD_SCALE
    );
    let eased = report(&mut manager, Duration::ZERO);
    assert!((eased - MAX_LOAD_SCALE / LOAD_STEP_DOWN).abs() < 1e-5, "{eased}");
    // (Down to 1 in as many steps as the bound takes, and one over.)
    let steps_down = (MAX_LOAD_SCALE.ln() / LOAD_STEP_DOWN.ln()).ceil() as usize;
    for _ in 0..steps_down {
        report(&mut manager, Duration::ZERO);
    }
    assert_eq!(manager.tolerance(), asked);
    // Reports that queued up between two frames count as one, the latest.
    for wait in [busy, busy, busy, Duration::ZERO, busy] {
        arrivals.send(Arrival::ServerLoad { wait }).unwrap();
    }
    assert_eq!(report(&mut manager, busy), LOAD_STEP_UP);
}

/// Over a link whose looks take longer than the default tolerance is tuned for, the
/// client's textures live longer in proportion to its shortest look lately — a single
/// slow look lifts nothing — and the server's load multiplies on top, within
/// `MAX_LOAD_SCALE` in all.
#[test]
fn a_long_link_lengthens_the_textures_lives() {
    use relief_client::manager::policy::{
        LINK_TUNED_ROUND_TRIP, LOAD_HIGH_WAIT, LOAD_STEP_UP, MAX_LOAD_SCALE,
    };

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let asked = Config::default().tolerance;
    let centre = scene.objects[index(&scene, "sphere")].world_bounds().center();
    // Takes `arrival` in with a frame; the tolerance then, over the user's.
    let tell = |manager: &mut Manager, arrivals: &UnboundedSender<Arrival>, arrival| {
        arrivals.send(arrival).unwrap();
        manager.frame(&scene, &camera_round(centre, 0.0), 0.0);
        manager.tolerance() / asked
    };
    let look = |round_trip| Arrival::LinkRoundTrip { round_trip };
    let load = |wait| Arrival::ServerLoad { wait };
    let busy = LOAD_HIGH_WAIT + Duration::from_millis(1);

    let (mut near, _commands, arrivals) = wired(&scene, Config::default());
    assert_eq!(
        tell(&mut near, &arrivals, look(LINK_TUNED_ROUND_TRIP / 2)),
        1.0,
        "a short link"
    );
    assert_eq!(
        tell(&mut near, &arrivals, look(LINK_TUNED_ROUND_TRIP * 3)),
        1.0,
        "one slow look"
    );

    let (mut far, _commands, arrivals) = wired(&scene, Config::default());
    assert!((tell(&mut far, &arrivals, look(LINK_TUNED_ROUND_TRIP * 2)) - 2.0).abs() < 1e-5);
    assert!(
        (tell(&mut far, &arrivals, look(LINK_TUNED_ROUND_TRIP * 3)) - 2.0).abs() < 1e-5,
        "the shortest counts"
    );
    assert_eq!(far.link_scale(), 2.0);
    // The server's load on top.
    assert!((tell(&mut far, &arrivals, load(busy)) - 2.0 * LOAD_STEP_UP).abs() < 1e-5);
    for _ in 0..20 {
        tell(&mut far, &arrivals, load(busy));
    }
    assert_eq!(far.tolerance() / asked, MAX_LOAD_SCALE);
    // The load's factor stopped where the two reached the bound: its first step down
    // shows at once.
    let eased = tell(&mut far, &arrivals, load(Duration::ZERO));
    assert!(eased < MAX_LOAD_SCALE, "{eased}");
}

/// A prediction's texture is counted by its arrival against the time it was predicted
/// to be needed: late by what it came after, early (negative) by what it came before.
#[test]
fn a_prediction_is_counted_late_or_early_against_its_need() {
    use relief_core::relief::DepthBits;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let sphere = index(&scene, "sphere");
    let centre = scene.objects[sphere].world_bounds().center();
    let tracer = ObjectTracer::new(&scene.objects[sphere]);
    // Orbits the sphere until a prediction is asked for; answers it `after` its need
    // (before, when negative); returns the lateness counted, ms.
    let lateness = |after_ms: i64| -> f64 {
        let (mut manager, mut commands, arrivals) = wired(&scene, Config::default());
        let request = (0..30)
            .find_map(|frame| {
                let t = frame as f32 / 30.0;
                manager.frame(&scene, &camera_round(centre, 30.0 * t), t as f64);
                std::iter::from_fn(|| commands.try_recv().ok()).find_map(|c| match c {
                    Command::Request(r) if r.needed_in_ms.is_some() && r.object == "sphere" => Some(r),
                    _ => None,
                })
            })
            .expect("a prediction for the sphere");
        let asked = std::time::Instant::now();
        let need = request.needed_in_ms.unwrap() as i64;
        let texture = bake(
            &tracer,
            scene.objects[sphere].to_world(request.eye).as_vec3(),
            64,
            DepthBits::Eight,
            relief_core::relief::SourceProjection::Perspective,
        )
        .unwrap();
        let arrive_at = asked + Duration::from_millis((need + after_ms).max(0) as u64);
        std::thread::sleep(arrive_at.saturating_duration_since(std::time::Instant::now()));
        let ready = ReadyTexture::new(texture, relief_render::impostor::Faces::Front);
        arrive(&arrivals, request.id, ready);
        manager.frame(&scene, &camera_round(centre, 30.0), 1.0);
        assert!(manager.counters.latencies_now_ms.is_empty());
        assert_eq!(manager.counters.prediction_lateness_ms.len(), 1);
        manager.counters.prediction_lateness_ms[0]
    };
    // (The request was sent a little before `asked`, and sleeps overrun: slack for a
    // loaded machine, well short of telling late from early.)
    let late = lateness(80);
    assert!((80.0..200.0).contains(&late), "late by {late} ms");
    let early = lateness(-150);
    assert!((-150.0..-40.0).contains(&early), "early by {early} ms");
}

/// Two placements of one knot, the second turned so that the camera sees it from the
/// same direction, in the knot's own frame, as the first: one texture serves both.
/// Only one is asked for (the second placement's need is covered by the first's
/// request), and when it arrives both show it. Turned far otherwise, each asks its
/// own.
#[test]
fn placements_seen_alike_share_one_texture() {
    // From the eye (0, 1.5, 8), the first knot lies along (−3, −0.5, −8) and the second
    // along (3, −0.5, −8): turned −41.1° about the vertical, the second sees the eye
    // where the first does.
    let twin = |yaw: f32| {
        let text = format!(
            r#"
            [[objects]]
            name = "knot"
            generator = {{ kind = "knot", p = 2, q = 3, segments = 720, sides = 32, tube_radius = 0.28 }}
            instances = [{{ translate = [-3, 1, 0] }}, {{ translate = [3, 1, 0], rotate_deg = [0, {yaw}, 0] }}]
            "#
        );
        Arc::new(Scene::parse(&text).unwrap())
    };
    let yaw = -2.0 * (3.0f32 / 8.0).atan().to_degrees();
    let camera = Camera::look_at(
        Vec3::new(0.0, 1.5, 8.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::Y,
        60.0,
        320,
        180,
    )
    .unwrap();
    // Frames from a still eye until both knots show an impostor: the requests asked
    // and the textures shared meanwhile.
    let run = |scene: &Arc<Scene>| {
        let mut manager = served_locally(scene, Config::default());
        let start = std::time::Instant::now();
        while !(manager.frame(scene, &camera, 0.0).iter()).all(|s| matches!(s, Show::Impostor { .. })) {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "textures did not arrive"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        let asked = manager.counters.requests_now + manager.counters.requests_predicted;
        (asked, manager.counters.textures_shared)
    };
    let (asked, shared) = run(&twin(yaw));
    assert_eq!((asked, shared), (1, 1), "one request, its texture shared");
    // Turned the other way, the second sees the eye some 150° round from where the
    // first does.
    let (asked, shared) = run(&twin(90.0));
    assert_eq!((asked, shared), (2, 0), "seen from far apart, each its own");
}

/// A texture the server made for a nearby eye (within the request's `serve_within`) is
/// held, and graded, under the eye it was made for.
#[test]
fn a_texture_for_a_nearby_eye_is_held_under_its_own_eye() {
    use relief_client::manager::policy::SERVE_REACH;
    use relief_core::relief::DepthBits;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let (mut manager, mut commands, arrivals) = wired(&scene, Config::default());
    let sphere = index(&scene, "sphere");
    let object = &scene.objects[sphere];
    let centre = object.world_bounds().center();
    let local_centre = object.local_bounds.center();
    let camera_at = |degrees: f32| {
        let eye = centre
            + Vec3::new(
                4.5 * degrees.to_radians().sin(),
                1.0,
                4.5 * degrees.to_radians().cos(),
            );
        Camera::look_at(eye, centre, Vec3::Y, 60.0, 160, 90).unwrap()
    };
    let camera = camera_at(0.0);
    manager.frame(&scene, &camera, 0.0);
    let first = request_now(&mut commands);
    // Nothing held: the reach is the valid angle's share.
    let distance = first.eye.distance(local_centre);
    assert!(
        first.serve_within > 0.0 && first.serve_within <= SERVE_REACH,
        "{first:?}"
    );
    // Answered with the texture of an eye 1° round, within that reach.
    let made_for = local_centre + glam::Quat::from_rotation_y(1f32.to_radians()) * (first.eye - local_centre);
    assert!(made_for.distance(first.eye) <= first.serve_within * distance);
    let texture = bake(
        &ObjectTracer::new(object),
        made_for,
        64,
        DepthBits::Eight,
        relief_core::relief::SourceProjection::Perspective,
    )
    .unwrap();
    arrive(
        &arrivals,
        first.id,
        ReadyTexture::new(texture, relief_render::impostor::Faces::Front),
    );
    let shows = manager.frame(&scene, &camera, 0.1);
    let shown = manager
        .describe(&scene, sphere, &shows[sphere], &camera)
        .expect("the sphere as an impostor");
    assert!(
        (shown.turn_deg - 1.0).abs() < 0.05,
        "held under the eye it was made for: {shown:?}"
    );
}

/// An eye orbiting the sphere asks for no eye within a degree of one answered before:
/// each texture asked for is kept as it comes and covers the eyes it was asked for.
/// Flies `frames` (30 a second, 640×360) round the sphere of `orbit-sphere` at
/// `degrees_per_s`, looking at it; every request is baked and answered at once, and
/// `seen(frame, request)` sees each as it goes out.
fn orbit_the_sphere_answered(
    scene: &Arc<Scene>,
    manager: &mut Manager,
    (commands, arrivals): (&mut UnboundedReceiver<Command>, &UnboundedSender<Arrival>),
    degrees_per_s: f32,
    frames: std::ops::Range<u32>,
    mut seen: impl FnMut(u32, &TextureRequest),
) {
    use relief_core::relief::DepthBits;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let object = &scene.objects[index(scene, "sphere")];
    let centre = object.world_bounds().center();
    let tracer = ObjectTracer::new(object);
    for frame in frames {
        let t = frame as f64 / 30.0;
        let eye = around(centre, (degrees_per_s * t as f32).to_radians());
        let camera = Camera::look_at(eye, centre, Vec3::Y, 60.0, 640, 360).unwrap();
        manager.frame(scene, &camera, t);
        while let Ok(command) = commands.try_recv() {
            let Command::Request(r) = command else {
                continue;
            };
            seen(frame, &r);
            let texture = bake(&tracer, r.eye, r.size, DepthBits::Eight, r.projection).unwrap();
            arrive(
                arrivals,
                r.id,
                ReadyTexture::new(texture, relief_render::impostor::Faces::Front),
            );
        }
    }
}

/// Every request is answered at once. (When a texture was also asked for to partner the
/// shown one, a pair of valid angles beyond the eye's future, that one — the farthest
/// held — went as it came when textures were kept by nearness to the eye alone, and was
/// asked for again in 6 frames running. The predictions alone land nearer, and this no
/// longer turns on the order `Held::relied_on` keeps.)
#[test]
fn an_orbit_asks_for_no_eye_twice() {
    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let config = Config {
        keep: 3,
        tolerance: 2.0,
        ..Config::default()
    };
    let (mut manager, mut commands, arrivals) = wired(&scene, config);
    let local_centre = scene.objects[index(&scene, "sphere")].local_bounds.center();
    let mut answered: Vec<Vec3> = Vec::new();
    let mut asked_again = Vec::new();
    // 10° a second for 4 s.
    let wires = (&mut commands, &arrivals);
    orbit_the_sphere_answered(&scene, &mut manager, wires, 10.0, 0..120, |frame, r| {
        let turn = |eye: &Vec3| {
            (*eye - local_centre)
                .angle_between(r.eye - local_centre)
                .to_degrees()
        };
        if answered.iter().any(|eye| turn(eye) < 1.0) {
            asked_again.push((frame, (r.eye - local_centre).normalize()));
        }
        answered.push(r.eye);
    });
    eprintln!(
        "{} textures asked for, {} asked for again",
        answered.len(),
        asked_again.len()
    );
    assert!(answered.len() >= 3, "the orbit asks for textures: {answered:?}");
    assert!(
        asked_again.is_empty(),
        "asked for again (frame, direction): {asked_again:?}"
    );
}

/// Orbiting the sphere, answered at once: each predicted texture is made as far past
/// the eye's future as it may be seen from alone (the band past its rim, its lone
/// turn), so one texture serves that turn behind its eye and as much ahead — an orbit
/// takes fewer than 20 (16 with a solid's lone turn of 15°; made just past the future
/// eye, the band's turn apart, it took 20 when the turn allowed 30°).
#[test]
fn an_orbit_spaces_its_textures_a_lone_reach_apart() {
    let scene = Arc::new(Scene::load("orbit-sphere").unwrap());
    let (mut manager, mut commands, arrivals) = wired(&scene, without_stand_ins());
    // 45° a second: one orbit in 8 s, after 1 s to settle.
    let wires = (&mut commands, &arrivals);
    orbit_the_sphere_answered(&scene, &mut manager, wires, 45.0, 0..30, |_, _| {});
    let stale_before = manager.counters.stale_frames;
    let mut asked = 0;
    let wires = (&mut commands, &arrivals);
    orbit_the_sphere_answered(&scene, &mut manager, wires, 45.0, 30..270, |_, _| asked += 1);
    eprintln!("{asked} textures asked for over one orbit");
    assert!((8..20).contains(&asked), "{asked} textures over one orbit");
    // … each in time and valid where it is shown.
    let stale = manager.counters.stale_frames - stale_before;
    assert_eq!(stale, 0, "{stale} stale frames over the orbit");
}

/// The view turning fast towards an object beyond what the predicted-view margin opens
/// (a corner of the path): its texture is asked for ahead; turning away, it is not.
#[test]
fn a_view_turning_towards_an_object_asks_for_it_ahead() {
    let scene = Scene::load("default").unwrap();
    let rock = scene.objects[index(&scene, "rock")].world_bounds().center();
    // The eye 8 m along +x of the rock, still; the rock 150° round from where it
    // looks, the view turning 150° a second towards it or away; half a second's round
    // trip, so after 8 frames (115° round, past the margin of the view as it is) the
    // view is foreseen 70° further round (for twice the 7/30 s the frames span).
    let eye = rock + Vec3::new(8.0, 0.5, 0.0);
    let asked = |towards: f32| {
        let config = Config {
            initial_latency: 0.5,
            ..Config::default()
        };
        let (mut manager, mut commands) = unanswered(&scene, config);
        let mut eyes = Vec::new();
        for frame in 0..8 {
            let t = frame as f32 / 30.0;
            // Round from −x (the rock) by 150° less the turn so far.
            let off = (150.0 - towards * 150.0 * t).to_radians();
            let target = eye + Vec3::new(-off.cos(), 0.0, off.sin());
            let sent = (eye, target, t as f64);
            eyes.extend(requests_from_frame(
                &mut manager,
                &mut commands,
                &scene,
                sent,
                "rock",
                true,
            ));
        }
        eyes
    };
    assert!(
        !asked(1.0).is_empty(),
        "turning towards the rock, nothing asked for it"
    );
    assert!(
        asked(-1.0).is_empty(),
        "turning away from the rock, its texture asked for"
    );
}
