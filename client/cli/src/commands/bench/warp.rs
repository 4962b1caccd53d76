//! `relief bench warp`: the display time of every method on one texture, against a
//! memcpy of its bytes and a naive per-texel eq. 3-1/3-2 measured in the same run.

use anyhow::Result;
use clap::Args;
use serde::Serialize;

use relief_core::relief::DepthBits;

use relief_client::manager::ReadyTexture;
use relief_lab::methods::{Method, display, draw, prepare};
use relief_lab::solo::Solo;
use relief_render::gbuffer::GBuffer;
use relief_render::impostor::{Faces, Impostor};
use relief_render::pyramid::{MAX_TEXEL_PIXELS, MIN_LEVEL_EDGE, Pyramid};
use relief_render::warp::Variant;
use relief_render::warp::params::WarpParams;
use relief_render::warp::prewarp::{prewarp, prewarp_split};
use relief_render::warp::sprite::Sprite;

use crate::{args, progress};
use relief_lab::timing::{median_ms, median_ms_after};

#[derive(Args)]
pub struct WarpArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Object whose relief texture is warped.
    #[arg(long, default_value = "knot")]
    object: String,
    /// Texture edge N (N² texels).
    #[arg(long, default_value = "256", value_parser = args::texture_size, allow_hyphen_values = true)]
    size: u32,
    /// Angle between the texture's eye and the displayed eye, degrees.
    #[arg(long, default_value = "5", allow_hyphen_values = true, value_parser = crate::args::finite)]
    angle: f32,
    /// Frame edge in pixels.
    #[arg(long, default_value = "512", value_parser = args::frame_edge)]
    frame_size: u32,
    /// Timed runs per measurement (the median is reported), after one warm-up.
    #[arg(long, default_value = "21", value_parser = clap::value_parser!(u32).range(1..=10000))]
    runs: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// One method's line of `relief bench warp --json`.
#[derive(Serialize)]
struct WarpTiming {
    /// Display into the frame's G-buffer: warp + reconstruction (+ texture mapping).
    ms: f64,
    texels_per_s: f64,
    /// `ms` over a memcpy of the texture's bytes.
    memcpy_ratio: f64,
    /// `ms` over the naive per-texel eq. 3-1/3-2 (no lookup table).
    naive_ratio: f64,
    /// Pre-warp alone (warp + hole filling in the source plane; table 8.1's quantity).
    #[serde(skip_serializing_if = "Option::is_none")]
    prewarp_ms: Option<f64>,
    /// The pre-warp split into the halves above and below the epipole on two threads.
    #[serde(skip_serializing_if = "Option::is_none")]
    prewarp_split_ms: Option<f64>,
    /// The texture mapping of the pre-warped image into the frame alone (the rest of
    /// `ms`).
    #[serde(skip_serializing_if = "Option::is_none")]
    map_ms: Option<f64>,
}

#[derive(Serialize)]
struct WarpReport {
    object: String,
    size: u32,
    texels: usize,
    angle_deg: f32,
    frame_size: u32,
    runs: u32,
    /// Copy of the texture's albedo, normal and depth bytes.
    memcpy_ms: f64,
    /// Eq. 3-1/3-2 per texel with the k's and divisions, no table.
    naive_ms: f64,
    /// The same with the lookup table (two additions, two multiplications).
    lut_ms: f64,
    methods: std::collections::BTreeMap<String, WarpTiming>,
    /// Table 8.1 as ratios: each pre-warp variant's `prewarp_ms` over interleaved's.
    table_8_1: std::collections::BTreeMap<String, f64>,
    /// Two interleaved pre-warps (of this texture) three ways: which way of using the
    /// cores is faster here.
    two_prewarps: TwoPrewarps,
    /// Pull–push reconstruction of a 1280×720 layer with one splat per 2×2 pixels.
    pullpush_1280x720_ms: f64,
    /// The same impostor seen from four times as far: the full texture against the
    /// pyramid level the resolution test picks (no texels the screen cannot show).
    multires: MultiRes,
    /// What a client spends on each texture it receives, before any frame shows it.
    taking_in: TakingIn,
}

/// A received texture's way into the client, ms (one core).
#[derive(Serialize)]
struct TakingIn {
    /// The wire message (its planes compressed) checked and decoded into a texture.
    decode_ms: f64,
    /// Made ready for the frame loop (`ReadyTexture::new`): its pyramid with each
    /// level's texel connectivity, critical points, rim and edge error.
    ready_ms: f64,
    /// Of which: the full level's connectivity and packed texels (`Impostor::new`).
    impostor_ms: f64,
    /// Of which: the whole pyramid, levels and connectivity (`Pyramid::new`).
    pyramid_ms: f64,
}

/// Two pre-warps on the machine's threads, ms for both.
#[derive(Serialize)]
struct TwoPrewarps {
    /// Each whole on a thread of its own, at once.
    own_threads_ms: f64,
    /// Each split into its halves across the threads, one after the other.
    split_in_turn_ms: f64,
    /// Each split, both at once: what a frame does with its impostors.
    split_at_once_ms: f64,
}

#[derive(Serialize)]
struct MultiRes {
    full_ms: f64,
    level: usize,
    level_size: u32,
    level_ms: f64,
    /// `full_ms / level_ms`.
    saving: f64,
}

pub fn run(args: WarpArgs) -> Result<()> {
    let runs = args.runs as usize;
    let bar = progress::spinner("baking");
    let scene = crate::args::load_scene(&args.scene)?;
    let solo = Solo::new(&scene, &args.object, 3.0)?;
    // (8-bit depth, as the thesis' table 8.1 measures; a client's 16-bit textures warp
    // through tables of 12-bit entries, `WarpLevels`, in the same loop.)
    let impostor = Impostor::new(solo.bake(solo.eye(0.0), args.size, DepthBits::Eight)?);
    let camera = solo.camera(solo.eye(args.angle), args.frame_size)?;
    let params = WarpParams::new(&impostor.texture, camera.eye_f32())
        .map_err(|e| anyhow::anyhow!("--angle {}: {e}", args.angle))?;
    let texture = &impostor.texture;
    let texels = texture.depth.len();
    bar.set_message("baselines");
    // Baselines, measured in the same run.
    let (mut albedo, mut normal, mut depth) = (
        texture.albedo.clone(),
        texture.normal.clone(),
        texture.depth.clone(),
    );
    let memcpy_ms = median_ms(runs, || {
        albedo.copy_from_slice(&texture.albedo);
        normal.copy_from_slice(&texture.normal);
        depth.copy_from_slice(&texture.depth);
        std::hint::black_box((&albedo, &normal, &depth));
    });
    let mut warped = vec![glam::Vec2::ZERO; texels];
    let c = texture.camera;
    let (w, empty, bits) = (c.width as usize, texture.depth_bits.empty(), texture.depth_bits);
    let naive_ms = median_ms(runs, || {
        let cc = c.origin - std::hint::black_box(camera.eye_f32());
        for (k, out) in warped.iter_mut().enumerate() {
            let q = texture.depth[k];
            if q == empty {
                continue;
            }
            let d = c.depth_near + q as f32 / bits.max_level() as f32 * (c.depth_far - c.depth_near);
            let k1 = c.f.dot(c.b.cross(cc)) / c.a.dot(c.b.cross(cc));
            let k2 = c.f.dot(cc.cross(c.a)) / c.b.dot(cc.cross(c.a));
            let k3 = c.f.dot(c.a.cross(c.b)) / cc.dot(c.a.cross(c.b));
            let (u, v) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
            *out = glam::Vec2::new((u - k1 * d) / (1.0 + k3 * d), (v - k2 * d) / (1.0 + k3 * d));
        }
        std::hint::black_box(&warped);
    });
    let lut_ms = median_ms(runs, || {
        for (k, out) in warped.iter_mut().enumerate() {
            let q = texture.depth[k];
            if q != empty {
                let entry = params.levels.entry(q) as usize;
                *out = params.warp((k % w) as f32 + 0.5, (k / w) as f32 + 0.5, entry);
            }
        }
        std::hint::black_box(&warped);
    });
    let mut gbuffer = GBuffer::new(camera.width, camera.height);
    let source_camera = solo.camera(solo.eye(0.0), args.frame_size)?;
    display(Method::Interleaved, &impostor, 0, &source_camera, &mut gbuffer)?;
    let sprite = Sprite::capture(&gbuffer, 0);
    let mut methods = std::collections::BTreeMap::new();
    for method in Method::ALL {
        bar.set_message(method.name());
        let ms = median_ms_after(
            runs,
            &mut gbuffer,
            |g| g.clear(),
            |gbuffer| match (method, &sprite) {
                (Method::Sprite, Some(s)) => s.draw(gbuffer),
                (Method::Sprite, None) => {}
                _ => drop(display(method, &impostor, 0, &camera, gbuffer)),
            },
        );
        let prewarp_ms = method.variant().map(|v| {
            median_ms(runs, || {
                drop(std::hint::black_box(prewarp(&impostor, &params, v)))
            })
        });
        let prewarp_split_ms = (method == Method::Interleaved).then(|| {
            median_ms(runs, || {
                drop(std::hint::black_box(prewarp_split(
                    &impostor,
                    &params,
                    Variant::Interleaved,
                    None,
                )))
            })
        });
        let map_ms = (method == Method::Interleaved).then(|| {
            median_ms_after(
                runs,
                &mut (GBuffer::new(camera.width, camera.height), None),
                |(gbuffer, prepared)| {
                    gbuffer.clear();
                    *prepared = prepare(method, &impostor, &camera).ok();
                },
                |(gbuffer, prepared)| {
                    if let Some(prepared) = prepared.take() {
                        let _ = draw(prepared, &impostor, 0, &camera, gbuffer);
                    }
                },
            )
        });
        methods.insert(
            method.name(),
            WarpTiming {
                ms,
                texels_per_s: texels as f64 / (ms * 1e-3),
                memcpy_ratio: ms / memcpy_ms,
                naive_ratio: ms / naive_ms,
                prewarp_ms,
                prewarp_split_ms,
                map_ms,
            },
        );
    }
    bar.set_message("two pre-warps");
    let two_prewarps = {
        use std::hint::black_box;
        let whole = || prewarp(&impostor, &params, Variant::Interleaved);
        let split = || prewarp_split(&impostor, &params, Variant::Interleaved, None);
        TwoPrewarps {
            own_threads_ms: median_ms(runs, || drop(black_box(rayon::join(whole, whole)))),
            split_in_turn_ms: median_ms(runs, || drop(black_box((split(), split())))),
            split_at_once_ms: median_ms(runs, || drop(black_box(rayon::join(split, split)))),
        }
    };
    bar.set_message("pull-push 1280x720");
    let pullpush_1280x720_ms = {
        use relief_lab::methods::pullpush::{DepthMargin, Layer, Splat, fill};
        let mut sparse = Layer::new(1280, 720);
        for y in (0..720).step_by(2) {
            for x in (0..1280).step_by(2) {
                sparse.pixels[y * 1280 + x] = Splat {
                    depth: 5.0 + (x as f32 * 0.01).sin(),
                    albedo: [128; 3],
                    normal: [128, 128, 255],
                };
            }
        }
        median_ms_after(
            runs,
            &mut sparse.clone(),
            |layer| layer.pixels.copy_from_slice(&sparse.pixels),
            |layer| {
                fill(layer, 2, |l| DepthMargin {
                    per_depth: 0.01 * (1 << l) as f32,
                    constant: 0.0,
                })
            },
        )
    };
    bar.set_message("multi-resolution");
    let multires = {
        let far_eye = solo.scene.objects[0].local_bounds.center()
            + (solo.eye(args.angle) - solo.scene.objects[0].local_bounds.center()) * 4.0;
        let far = relief_core::camera::Camera {
            eye: far_eye.as_dvec3(),
            ..camera
        };
        let pyramid = Pyramid::new(impostor.texture.clone(), MIN_LEVEL_EDGE);
        let level = pyramid.level_for(&far, MAX_TEXEL_PIXELS);
        let mut time = |imp: &Impostor| {
            median_ms_after(
                runs,
                &mut gbuffer,
                |g| g.clear(),
                |g| {
                    let _ = display(Method::Interleaved, imp, 0, &far, g);
                },
            )
        };
        let (full_ms, level_ms) = (time(&pyramid.levels[0]), time(&pyramid.levels[level]));
        MultiRes {
            full_ms,
            level,
            level_size: pyramid.levels[level].texture.camera.width,
            level_ms,
            saving: full_ms / level_ms,
        }
    };
    bar.set_message("taking a texture in");
    let taking_in = {
        // (As a client receives it, its planes compressed; but with 8-bit depth, half
        // the depth bytes a client's 16 bits take.)
        let wire = relief_proto::planes::compressed(relief_proto::convert::texture_to_pb(texture));
        let decode =
            || relief_proto::convert::texture_from_pb("texture", &wire).map_err(|e| anyhow::anyhow!("{e}"));
        let decoded = decode()?;
        TakingIn {
            decode_ms: median_ms(runs, || {
                let _ = std::hint::black_box(decode());
            }),
            ready_ms: median_ms(runs, || {
                std::hint::black_box(ReadyTexture::new(decoded.clone(), Faces::Both));
            }),
            impostor_ms: median_ms(runs, || {
                std::hint::black_box(Impostor::new(decoded.clone()));
            }),
            pyramid_ms: median_ms(runs, || {
                std::hint::black_box(Pyramid::new(decoded.clone(), MIN_LEVEL_EDGE));
            }),
        }
    };
    bar.finish_and_clear();
    let interleaved = methods
        .get("interleaved")
        .and_then(|t: &WarpTiming| t.prewarp_ms)
        .unwrap_or(f64::NAN);
    let table_8_1 = methods
        .iter()
        .filter_map(|(name, t)| t.prewarp_ms.map(|ms| (name.clone(), ms / interleaved)))
        .collect();
    let report = WarpReport {
        object: args.object,
        size: args.size,
        texels,
        angle_deg: args.angle,
        frame_size: args.frame_size,
        runs: args.runs,
        memcpy_ms,
        naive_ms,
        lut_ms,
        methods,
        table_8_1,
        two_prewarps,
        pullpush_1280x720_ms,
        multires,
        taking_in,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} {}² ({} texels), {}° turn, {}² frame; memcpy {:.4} ms, naive eq. 3-1/3-2 {:.4} ms, with table {:.4} ms",
        report.object,
        report.size,
        report.texels,
        report.angle_deg,
        report.frame_size,
        memcpy_ms,
        naive_ms,
        lut_ms
    );
    println!(
        "pull-push 1280x720: {:.3} ms; multi-resolution at 4x the distance: full {:.3} ms, level {} ({}²) {:.3} ms ({:.1}x)",
        report.pullpush_1280x720_ms,
        report.multires.full_ms,
        report.multires.level,
        report.multires.level_size,
        report.multires.level_ms,
        report.multires.saving
    );
    let t = &report.taking_in;
    println!(
        "taking the texture in: decode {:.3} ms, made ready {:.3} ms (of which the pyramid {:.3} ms, its full level's connectivity {:.3} ms)",
        t.decode_ms, t.ready_ms, t.pyramid_ms, t.impostor_ms
    );
    let table: Vec<String> = report
        .table_8_1
        .iter()
        .map(|(k, v)| format!("{k} {v:.2}"))
        .collect();
    println!("table 8.1 (pre-warp time over interleaved): {}", table.join(", "));
    let two = &report.two_prewarps;
    println!(
        "two interleaved pre-warps: each on its own thread {:.3} ms, each split in turn {:.3} ms, both split at once {:.3} ms",
        two.own_threads_ms, two.split_in_turn_ms, two.split_at_once_ms
    );
    println!(
        "{:<18} {:>9} {:>11} {:>9} {:>9} {:>11} {:>11} {:>9}",
        "method", "ms", "Mtexels/s", "/memcpy", "/naive", "prewarp ms", "split ms", "map ms"
    );
    for (name, t) in &report.methods {
        let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
        println!(
            "{name:<18} {:>9.3} {:>11.1} {:>9.1} {:>9.1} {:>11} {:>11} {:>9}",
            t.ms,
            t.texels_per_s / 1e6,
            t.memcpy_ratio,
            t.naive_ratio,
            opt(t.prewarp_ms),
            opt(t.prewarp_split_ms),
            opt(t.map_ms)
        );
    }
    Ok(())
}
