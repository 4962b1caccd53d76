//! The demo's optional window: each frame shown as it is drawn. Built with the
//! `window` feature; without it, asking for a window is a clear error.

use anyhow::Result;

use relief_core::frame::Frame;

/// A window showing frames, or the reason there can be none.
pub struct Viewer {
    #[cfg(feature = "window")]
    window: minifb::Window,
    #[cfg(feature = "window")]
    pixels: Vec<u32>,
}

impl Viewer {
    /// Opens a `width × height` window titled `title`.
    #[cfg(feature = "window")]
    pub fn open(title: &str, width: u32, height: u32) -> Result<Viewer> {
        let mut window = minifb::Window::new(
            title,
            width as usize,
            height as usize,
            minifb::WindowOptions::default(),
        )
        .map_err(|e| anyhow::anyhow!("cannot open a window (is there a display? DISPLAY unset?): {e}"))?;
        // The flight paces itself; the window must not add waits of its own.
        window.set_target_fps(0);
        Ok(Viewer {
            window,
            pixels: vec![0; width as usize * height as usize],
        })
    }

    #[cfg(not(feature = "window"))]
    pub fn open(_title: &str, _width: u32, _height: u32) -> Result<Viewer> {
        anyhow::bail!(
            "this relief was built without a window: build it with \
             `cargo build --release --features relief/window`"
        )
    }

    /// Shows `frame`; false once the person closed the window or pressed Escape.
    #[cfg(feature = "window")]
    pub fn show(&mut self, frame: &Frame) -> Result<bool> {
        if !self.window.is_open() || self.window.is_key_down(minifb::Key::Escape) {
            return Ok(false);
        }
        for (out, [r, g, b]) in self.pixels.iter_mut().zip(&frame.color) {
            *out = (*r as u32) << 16 | (*g as u32) << 8 | *b as u32;
        }
        self.window
            .update_with_buffer(&self.pixels, frame.width as usize, frame.height as usize)
            .map_err(|e| anyhow::anyhow!("updating the window: {e}"))?;
        Ok(true)
    }

    #[cfg(not(feature = "window"))]
    pub fn show(&mut self, _frame: &Frame) -> Result<bool> {
        Ok(false)
    }
}
