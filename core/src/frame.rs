//! A rendered frame: colour plus the object each pixel shows.

use std::path::Path;

use crate::error::{Error, Result};

/// `object` value of a pixel that shows no object.
pub const NO_OBJECT: u32 = u32::MAX;

/// An RGB8 frame with a per-pixel object index (into the scene's objects).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Row-major, `y * width + x`, y downwards.
    pub color: Vec<[u8; 3]>,
    pub object: Vec<u32>,
}

impl Frame {
    /// A frame filled with `background` and no objects.
    pub fn new(width: u32, height: u32, background: [u8; 3]) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width,
            height,
            color: vec![background; n],
            object: vec![NO_OBJECT; n],
        }
    }

    /// Writes the colour as an RGB8 PNG, creating the parent directory.
    pub fn save_png(&self, path: &Path) -> Result<()> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        let bytes: Vec<u8> = self.color.iter().flatten().copied().collect();
        image::save_buffer(path, &bytes, self.width, self.height, image::ColorType::Rgb8)
            .map_err(|e| Error::io(path, std::io::Error::other(e)))
    }
}
