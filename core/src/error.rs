//! The error type of `relief-core`: every variant names what was wrong.

use std::path::PathBuf;

/// Errors from loading and validating scenes, meshes and relief textures.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    /// (The I/O error is part of the message, not a `source`: error chains printed
    /// with `{:#}` would say it twice.)
    #[error("{}: {error}", path.display())]
    Io { path: PathBuf, error: std::io::Error },
    /// A model file (Wavefront OBJ, glTF) is malformed or holds no usable triangles.
    #[error("{}: {message}", path.display())]
    Obj { path: PathBuf, message: String },
    /// A scene file is malformed or inconsistent.
    #[error("scene {origin}: {message}")]
    Scene { origin: String, message: String },
    /// `--scene` named neither a built-in scene nor an existing file.
    #[error(
        "unknown scene `{0}`: give a built-in scene name ({builtins}), a .toml scene file, or an .obj, .gltf or .glb file",
        builtins = crate::scene::builtin_names().join(", ")
    )]
    UnknownScene(String),
    /// An object name that the scene does not hold.
    #[error("scene `{scene}` has no object named `{name}` (it has: {available})")]
    UnknownObject {
        scene: String,
        name: String,
        available: String,
    },
    /// A relief texture on disk is malformed.
    #[error("relief texture {}: {message}", path.display())]
    Texture { path: PathBuf, message: String },
    /// A scene that would cost more than its loader allows (see
    /// [`SceneLimits`](crate::scene::SceneLimits)), found before it is built.
    #[error("the scene is too large: {0}")]
    TooCostly(String),
    /// An argument is out of range or not finite.
    #[error("{0}")]
    Invalid(String),
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            error: source,
        }
    }
}
