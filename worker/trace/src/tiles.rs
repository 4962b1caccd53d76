//! The one way images are split across threads: bands of [`TILE`] rows in parallel
//! (rayon), each band cut into `TILE × TILE` blocks, so neighbouring rays are traced
//! together and share cache lines of the BVH.

use rayon::prelude::*;

/// Edge of a tile, in pixels.
pub const TILE: usize = 8;

/// A block of an image: pixel `(x0 + dx, y0 + dy)` for `dx < width`, `dy < height`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

impl Block {
    /// The block's pixels, row by row.
    pub fn pixels(self) -> impl Iterator<Item = (u32, u32)> {
        (self.y0..self.y0 + self.height)
            .flat_map(move |y| (self.x0..self.x0 + self.width).map(move |x| (x, y)))
    }

    /// The block cut into blocks of at most `TILE × TILE`, row by row, each row left to
    /// right.
    pub fn tiles(self) -> impl Iterator<Item = Block> {
        let tile = TILE as u32;
        let (x_end, y_end) = (self.x0 + self.width, self.y0 + self.height);
        (self.y0..y_end).step_by(TILE).flat_map(move |y0| {
            (self.x0..x_end).step_by(TILE).map(move |x0| Block {
                x0,
                y0,
                width: tile.min(x_end - x0),
                height: tile.min(y_end - y0),
            })
        })
    }
}

/// Fills the row-major `width × height` image `out` block by block: `shade(block,
/// values)` must write the block's pixels into `values` in [`Block::pixels`] order.
///
/// # Panics
/// If `out.len() != width * height` (a caller bug, not an input error).
pub fn par_fill_blocks<T, F>(width: u32, height: u32, out: &mut [T], shade: F)
where
    T: Send + Copy + Default,
    F: Fn(Block, &mut Vec<T>) + Sync,
{
    let w = width as usize;
    assert_eq!(out.len(), w * height as usize, "image buffer size");
    if w == 0 {
        return;
    }
    out.par_chunks_mut(w * TILE).enumerate().for_each_init(
        || Vec::with_capacity(TILE * TILE),
        |values, (band, rows)| {
            for block in band_blocks(width, band, rows.len() / w) {
                values.clear();
                shade(block, values);
                debug_assert_eq!(values.len(), (block.width * block.height) as usize);
                let x0 = block.x0 as usize;
                for (dy, row) in values.chunks(block.width as usize).enumerate() {
                    rows[dy * w + x0..dy * w + x0 + row.len()].copy_from_slice(row);
                }
            }
        },
    );
}

/// The blocks of band `band` (rows `band · TILE ..`, `band_height` of them) of an image
/// `width` wide, left to right: how [`par_fill_blocks`] cuts each band, for callers
/// that fill several planes at once.
pub fn band_blocks(width: u32, band: usize, band_height: usize) -> impl Iterator<Item = Block> {
    Block {
        x0: 0,
        y0: (band * TILE) as u32,
        width,
        height: band_height as u32,
    }
    .tiles()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_a_block_once_within_tile() {
        let block = Block {
            x0: 5,
            y0: 3,
            width: 19,
            height: 9,
        };
        let mut seen: Vec<(u32, u32)> = block.tiles().flat_map(Block::pixels).collect();
        assert!(
            block
                .tiles()
                .all(|t| t.width as usize <= TILE && t.height as usize <= TILE)
        );
        seen.sort_by_key(|&(x, y)| (y, x));
        assert_eq!(seen, block.pixels().collect::<Vec<_>>());
    }

    #[test]
    fn every_pixel_once() {
        for (w, h) in [(1, 1), (8, 8), (13, 29), (64, 3)] {
            let mut out = vec![(u32::MAX, u32::MAX); (w * h) as usize];
            par_fill_blocks(w, h, &mut out, |block, values| values.extend(block.pixels()));
            for (k, &(x, y)) in out.iter().enumerate() {
                assert_eq!((y * w + x) as usize, k);
            }
        }
    }
}
