//! Where a scene's loaders may read files. A scene the user names on the command line
//! may refer to any file; a scene uploaded to a server by anyone who can reach it may
//! only read the files it brought: the server must never open its own disk for it.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The files a scene's loaders may open.
#[derive(Debug, Clone, Copy)]
pub enum Reach<'a> {
    /// Any file (scenes given by the user).
    Anywhere,
    /// Only regular files inside this directory, symbolic links resolved (scenes
    /// uploaded by others).
    Within(&'a Path),
}

impl Reach<'_> {
    /// `path`, if the loaders may open it; else an error naming it.
    pub fn check(&self, path: &Path) -> Result<PathBuf> {
        let Reach::Within(root) = self else {
            return Ok(path.to_path_buf());
        };
        let outside = || Error::Invalid(format!("`{}` lies outside the scene's own files", path.display()));
        let root = root.canonicalize().map_err(|e| Error::io(root, e))?;
        // (A missing file is outside too: the scene brought no such file.)
        let resolved = path.canonicalize().map_err(|_| outside())?;
        if resolved.starts_with(&root) && resolved.is_file() {
            Ok(resolved)
        } else {
            Err(outside())
        }
    }
}
