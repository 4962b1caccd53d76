//! Argument parsers shared by the commands.

use anyhow::anyhow;
use clap::Args;
use glam::{DVec3, Vec3};

use relief_core::camera::Camera;
use relief_core::scene::Scene;

use relief_core::camera::MAX_FRAME_SIZE;
use relief_core::relief::MAX_TEXTURE_SIZE;

/// `X,Y,Z`, finite.
pub fn vec3(text: &str) -> Result<Vec3, String> {
    relief_core::vector::parse_vec3(text).map_err(|e| e.to_string())
}

/// A position `X,Y,Z` in the world, finite: `f64`, since a world may lie far from its
/// origin.
pub fn position(text: &str) -> Result<DVec3, String> {
    relief_core::vector::parse_dvec3(text).map_err(|e| e.to_string())
}

/// A finite number.
pub fn finite(text: &str) -> Result<f32, String> {
    let v: f32 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    if !v.is_finite() {
        return Err(format!("{v} is not finite"));
    }
    Ok(v)
}

/// A finite number above zero.
pub fn positive(text: &str) -> Result<f32, String> {
    match finite(text)? {
        v if v > 0.0 => Ok(v),
        v => Err(format!("{v} must be above zero")),
    }
}

/// A fraction, in [0, 1].
pub fn fraction(text: &str) -> Result<f64, String> {
    match finite(text)? {
        v if (0.0..=1.0).contains(&v) => Ok(v as f64),
        v => Err(format!("{v} must be a fraction in [0, 1]")),
    }
}

/// A vertical field of view in degrees, in (0, 180).
pub fn fov(text: &str) -> Result<f32, String> {
    match finite(text)? {
        v if v > 0.0 && v < 180.0 => Ok(v),
        v => Err(format!("field of view {v} must be in (0, 180) degrees")),
    }
}

/// A `*.png` output path (the extension names the format written).
pub fn png_path(text: &str) -> Result<std::path::PathBuf, String> {
    let path = std::path::PathBuf::from(text);
    match path.extension() {
        Some(e) if e.eq_ignore_ascii_case("png") => Ok(path),
        _ => Err(format!("`{text}`: the output is a PNG image; name it *.png")),
    }
}

/// Checks, before any work, that an output file can be written at `path`, so that a
/// bad `--out` fails at once instead of after the work: an existing file must take
/// writes (it is opened, not truncated); else its directory is created and must take a
/// new file (a probe of our own, created and removed — the user's path itself is not
/// created). `path` must not be a directory.
pub fn ensure_writable(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    let context = || format!("{flag} {}", path.display());
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => return Err(anyhow!("{}: is a directory", context())),
        // An existing file must take writes (opened without creating or truncating).
        Ok(m) if m.is_file() => {
            std::fs::OpenOptions::new()
                .append(true)
                .open(path)
                .map_err(|e| anyhow!("{}: {e}", context()))?;
            return Ok(());
        }
        _ => {}
    }
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    let dir = parent.unwrap_or(std::path::Path::new("."));
    std::fs::create_dir_all(dir)
        .and_then(|()| relief_core::scratch::probe_writable(dir))
        .map_err(|e| anyhow!("{}: {e}", context()))
}

/// A whole number in `1 ..= max`.
fn count_up_to(text: &str, max: u32) -> Result<u32, String> {
    let n: u32 = text
        .parse()
        .map_err(|_| format!("`{text}` is not a whole number"))?;
    if n == 0 || n > max {
        return Err(format!("{n} is out of range: must be 1 ..= {max}"));
    }
    Ok(n)
}

/// A relief-texture edge in texels: `1 ..= MAX_TEXTURE_SIZE`.
pub fn texture_size(text: &str) -> Result<u32, String> {
    count_up_to(text, MAX_TEXTURE_SIZE)
}

/// `WxH` frame size, each in `1 ..= MAX_FRAME_SIZE`.
pub fn frame_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{text}` is not WIDTHxHEIGHT"))?;
    Ok((frame_edge(w)?, frame_edge(h)?))
}

/// One frame edge: `1 ..= MAX_FRAME_SIZE`.
pub fn frame_edge(text: &str) -> Result<u32, String> {
    count_up_to(text, MAX_FRAME_SIZE)
}

/// 8 or 16.
pub fn depth_bits(text: &str) -> Result<u32, String> {
    match text {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("`{text}` is not 8 or 16")),
    }
}

/// The scene and camera of a rendered frame, shared by `reference` and `frame`.
#[derive(Args)]
pub struct View {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    pub scene: String,
    /// Camera position, X,Y,Z.
    #[arg(long, value_parser = position, allow_hyphen_values = true)]
    pub eye: DVec3,
    /// Point the camera looks at, X,Y,Z.
    #[arg(long, value_parser = position, allow_hyphen_values = true)]
    pub target: DVec3,
    /// Up direction, X,Y,Z.
    #[arg(long, default_value = "0,1,0", value_parser = vec3, allow_hyphen_values = true)]
    pub up: Vec3,
    /// Vertical field of view in degrees (default: the scene's).
    #[arg(long, allow_hyphen_values = true, value_parser = fov)]
    pub fov: Option<f32>,
    /// Frame size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = frame_size)]
    pub size: (u32, u32),
}

/// Loads the scene `spec` (`--scene`), saying on stderr which of its objects' meshes
/// lie too far from their own origin for `f32` to place finely
/// ([`Scene::precision_warnings`]).
pub fn load_scene(spec: &str) -> anyhow::Result<Scene> {
    let scene = Scene::load(spec)?;
    for warning in scene.precision_warnings() {
        eprintln!("warning: {warning}");
    }
    Ok(scene)
}

impl View {
    /// Loads the scene and makes the camera; errors name the bad argument.
    pub fn load(&self) -> anyhow::Result<(Scene, Camera)> {
        let scene = load_scene(&self.scene)?;
        let fov = self.fov.unwrap_or(scene.fov_y_degrees);
        let (w, h) = self.size;
        let camera = Camera::look_at(self.eye, self.target, self.up, fov, w, h).map_err(|e| anyhow!(e))?;
        Ok((scene, camera))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(frame_size("640x480"), Ok((640, 480)));
        assert!(frame_size("0x480").is_err());
        assert!(frame_size("640").is_err());
        assert!(texture_size("0").is_err());
        assert!(texture_size("4097").is_err());
        assert_eq!(texture_size("256"), Ok(256));
    }
}

/// `--projection`: which way a texture's texels' rays go.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ProjectionArg {
    Orthographic,
    Perspective,
}

impl From<ProjectionArg> for relief_core::relief::SourceProjection {
    fn from(p: ProjectionArg) -> Self {
        match p {
            ProjectionArg::Orthographic => Self::Orthographic,
            ProjectionArg::Perspective => Self::Perspective,
        }
    }
}
