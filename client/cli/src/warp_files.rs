//! Pre-warps kept from a flight, on disk: `relief demo --warp-samples K` writes each
//! [`WarpSample`] as a directory, and `relief bench replay` reads them back one at a
//! time ([`SavedWarp`]) to time the flight's own pre-warps again, alone.
//!
//! A directory holds the texture level the pre-warp warped
//! ([`ReliefTexture::write_dir`]: `albedo.png`, `normal.png`, `depth.png`,
//! `texture.json`) and `warp.json` ([`WarpFile`]): the object, the camera in the
//! object's frame, the faces shown, and what the flight measured.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use relief_client::manager::WarpSample;
use relief_client::manager::policy::MAX_WARP_SAMPLES;
use relief_core::camera::Camera;
use relief_core::relief::ReliefTexture;
use relief_core::scene::Scene;
use relief_render::impostor::{Faces, Impostor};

/// The name of each sample's description in its directory.
const WARP_JSON: &str = "warp.json";

/// How far a saved camera's axes may lie from those `Camera::look_at` makes of them.
const AXIS_TOLERANCE: f32 = 1e-4;

/// `warp.json`: all a pre-warp was given but the texture, and what it cost in the
/// flight.
#[derive(Serialize, Deserialize)]
struct WarpFile {
    /// The object's name in the scene.
    object: String,
    /// The frame's camera in the object's frame, every field as it was (so the replay
    /// warps exactly what the flight did).
    eye: [f64; 3],
    forward: [f32; 3],
    right: [f32; 3],
    up: [f32; 3],
    fov_y: f32,
    width: u32,
    height: u32,
    /// Whether back faces were left out (`front`) or shown (`both`).
    faces: String,
    /// A partner texture, drawn behind the first.
    partner: bool,
    /// Texels the flight's pre-warp visited.
    visited: usize,
    /// Its time in the flight's frame, ms.
    in_frame_ms: f64,
}

/// A kept pre-warp read back: the impostor and camera to warp it with again.
pub struct SavedWarp {
    pub dir: PathBuf,
    pub object: String,
    pub impostor: Impostor,
    pub camera: Camera,
    pub partner: bool,
    /// Texels the flight's pre-warp visited.
    pub visited: usize,
    /// Its time in the flight's frame, ms.
    pub in_frame_ms: f64,
}

/// Writes `samples` into `dir`, one directory each, `NNNN-object`: `dir` is made anew
/// (a run's own output: what an earlier run kept there would be replayed as this
/// one's).
pub fn write_samples(dir: &Path, samples: &[WarpSample], scene: &Scene) -> Result<()> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).with_context(|| format!("clearing {}", dir.display()))?;
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (n, sample) in samples.iter().enumerate() {
        // (A scene's names are fit for file names: `check_object_name`.)
        let object = scene
            .objects
            .get(sample.object)
            .map_or_else(|| format!("object{}", sample.object), |o| o.name.clone());
        let at = dir.join(format!("{n:04}-{object}"));
        let impostor = sample.impostor();
        impostor
            .texture
            .write_dir(&at)
            .with_context(|| format!("writing {}", at.display()))?;
        let c = &sample.camera;
        let file = WarpFile {
            object,
            eye: c.eye.to_array(),
            forward: c.forward.to_array(),
            right: c.right.to_array(),
            up: c.up.to_array(),
            fov_y: c.fov_y,
            width: c.width,
            height: c.height,
            faces: match impostor.faces {
                Faces::Front => "front",
                Faces::Both => "both",
            }
            .into(),
            partner: sample.partner,
            visited: sample.visited,
            in_frame_ms: sample.in_frame_ms,
        };
        let path = at.join(WARP_JSON);
        std::fs::write(&path, serde_json::to_string_pretty(&file)? + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The sample directories in `dir` (those holding a `warp.json`), in name order, each
/// to be read with [`read_sample`]: at most [`MAX_WARP_SAMPLES`], as many as a run
/// keeps.
pub fn sample_dirs(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))?;
    let mut dirs = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("reading {}", dir.display()))?
            .path();
        if path.join(WARP_JSON).is_file() {
            dirs.push(path);
        }
    }
    if dirs.is_empty() {
        bail!(
            "{}: no kept pre-warps (directories with a {WARP_JSON}; `relief demo --warp-samples K` writes them to OUT/warps)",
            dir.display()
        );
    }
    if dirs.len() > MAX_WARP_SAMPLES {
        bail!(
            "{}: {} kept pre-warps, more than a run keeps ({MAX_WARP_SAMPLES})",
            dir.display(),
            dirs.len()
        );
    }
    dirs.sort();
    Ok(dirs)
}

/// The sample in `dir`; errors name the file and what is wrong.
pub fn read_sample(dir: &Path) -> Result<SavedWarp> {
    let path = dir.join(WARP_JSON);
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let file: WarpFile = serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let faces = match file.faces.as_str() {
        "front" => Faces::Front,
        "both" => Faces::Both,
        other => bail!(
            "{}: faces {other:?}: expected \"front\" or \"both\"",
            path.display()
        ),
    };
    let (eye, [forward, right, up]) = (
        DVec3::from_array(file.eye),
        [file.forward, file.right, file.up].map(Vec3::from_array),
    );
    // A camera as `Camera::look_at` makes one from the saved eye, forward, up, field of
    // view and size (its checks, its errors), whose axes the saved ones are to rounding:
    // unit, square and right-handed. (The saved ones are kept, as the flight had them.)
    let made = Camera::look_at(
        eye,
        eye + forward.as_dvec3(),
        up,
        file.fov_y.to_degrees(),
        file.width,
        file.height,
    )
    .with_context(|| format!("{}: the camera", path.display()))?;
    let near = |a: Vec3, b: Vec3| a.distance(b) < AXIS_TOLERANCE;
    if !(near(made.forward, forward) && near(made.right, right) && near(made.up, up)) {
        bail!(
            "{}: the camera's axes are not unit, square and right-handed (not those of a camera looking along its forward with its up)",
            path.display()
        );
    }
    let texture =
        ReliefTexture::read_dir(dir).with_context(|| format!("reading the texture in {}", dir.display()))?;
    Ok(SavedWarp {
        dir: dir.to_path_buf(),
        object: file.object,
        impostor: Impostor::new(texture).with_faces(faces),
        camera: Camera {
            eye,
            forward,
            right,
            up,
            fov_y: file.fov_y,
            width: file.width,
            height: file.height,
        },
        partner: file.partner,
        visited: file.visited,
        in_frame_ms: file.in_frame_ms,
    })
}
