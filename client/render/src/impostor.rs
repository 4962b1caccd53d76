//! A relief texture prepared for display: the texture plus what every warp of it needs
//! and that does not depend on the eye — computed once when the texture arrives.

use std::collections::HashMap;

use glam::Vec2;
use relief_core::joins::{join_reach, slope_along};
use relief_core::relief::{ReliefTexture, TEXEL_SIDES, decode_normal_rgb8};

use crate::warp::params::WarpLevels;
use crate::warp::prewarp::pack_texel;

/// Which sides of an object's surfaces can show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Faces {
    /// Both: open surfaces (leaves, a plane) show their back from behind.
    #[default]
    Both,
    /// The front only: a closed surface ([`Mesh::is_closed`](relief_core::mesh::Mesh::is_closed))
    /// hides its back. The pre-warp leaves out texels turned away from the eye — seen
    /// by the texture's eye, hidden from this one — which would otherwise land past the
    /// silhouette as fringes.
    Front,
}

impl Faces {
    /// The faces of `object` that can show: the front only for a closed surface.
    pub fn of(object: &relief_core::scene::SceneObject) -> Faces {
        if object.is_closed() {
            Faces::Front
        } else {
            Faces::Both
        }
    }
}

/// The texels of a texture holding surface, bounded: the rectangle of texel rows and
/// columns they lie in and the depth-table entries
/// ([`WarpLevels::entry`]) they take. A pre-warp lands only these, so the warp of
/// the rectangle's corners at the first and last entries bounds its image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SurfaceExtent {
    /// The texel columns, from the leftmost holding surface to one past the rightmost.
    pub columns: std::ops::Range<usize>,
    /// The texel rows, likewise.
    pub rows: std::ops::Range<usize>,
    /// The lowest and the highest table entry they take, both included.
    pub entries: std::ops::RangeInclusive<u16>,
}

impl SurfaceExtent {
    /// The extent of the surface texels of a texture whose rows hold surface over
    /// `occupied` (as [`Impostor::occupied`]), at depth-table `entries` (one per
    /// surface texel); `None` when no row holds any.
    fn of(occupied: &[std::ops::Range<usize>], entries: impl Iterator<Item = u16>) -> Option<SurfaceExtent> {
        let rows = || {
            occupied
                .iter()
                .enumerate()
                .filter(|(_, texels)| !texels.is_empty())
        };
        let (first, _) = rows().next()?;
        let (last, _) = rows().next_back()?;
        let left = rows().map(|(_, texels)| texels.start).min()?;
        let right = rows().map(|(_, texels)| texels.end).max()?;
        let (lowest, highest) = entries.fold((u16::MAX, 0), |(lo, hi), q| (lo.min(q), hi.max(q)));
        Some(SurfaceExtent {
            columns: left..right,
            rows: first..last + 1,
            entries: lowest..=highest,
        })
    }
}

/// A relief texture and its texel connectivity.
///
/// Two neighbouring texels belong to one surface when their depth difference is what
/// their normals' slope allows over one texel (with slack), so the warps interpolate
/// between them; otherwise there is a depth discontinuity (one surface in front of
/// another) and nothing is interpolated across it.
#[derive(Debug, Clone, PartialEq)]
pub struct Impostor {
    pub texture: ReliefTexture,
    /// Texel `k` is connected to its right neighbour. (Also packed into
    /// [`Impostor::packed`], which the pre-warp reads: set both, or make the impostor
    /// anew.)
    pub right: Vec<bool>,
    /// Texel `k` is connected to the neighbour below (packed too, as `right`).
    pub down: Vec<bool>,
    /// Texel `k`'s albedo, encoded normal, its depth's table entry
    /// ([`WarpLevels::entry`]) and its links packed in one word: all the pre-warp reads
    /// of a texel, in one load (measured: 8 % of its time).
    pub packed: Vec<u64>,
    /// Each row's texels from its first surface texel to one past its last (empty for
    /// a row without one): the pre-warp visits no more of the row. (A compact object's
    /// texture is empty around it: the knot's 256² texture, 32 % of its texels.)
    pub occupied: Vec<std::ops::Range<usize>>,
    /// Where its surface texels lie, `None` when it has none: all of the texture that can
    /// land in a pre-warp, which sizes its image by it. (Made from `texture` with
    /// [`Impostor::occupied`]: change the texture, and make the impostor anew.)
    pub surface: Option<SurfaceExtent>,
    /// Which sides of the surfaces can show.
    pub faces: Faces,
    /// Where a deeper surface seen past a step down along a row ends, hidden behind the
    /// step's near texel ([`Hidden`](relief_core::relief::Hidden) entries beside a
    /// covered neighbour): keyed by [`Impostor::outline_key`], the outline's point in
    /// texel coordinates and its displacement. The pre-warp fills a crack from that
    /// surface no nearer the step than where the outline lands; past it the eye sees
    /// beyond the surface. (Made from `texture`'s list: change it, and make the impostor
    /// anew.)
    pub outlines: HashMap<u32, (Vec2, f32)>,
}

impl Impostor {
    pub fn new(texture: ReliefTexture) -> Impostor {
        let c = texture.camera;
        let (w, h) = (c.width as usize, c.height as usize);
        let empty = texture.depth_bits.empty();
        let quantum = c.depth_quantum(texture.depth_bits);
        let (a_len, b_len) = (c.a.length(), c.b.length());
        let (a_dir, b_dir) = (c.a / a_len, c.b / b_len);
        let depth = |k: usize| c.depth_of_level(texture.depth[k], texture.depth_bits);
        // How much wider than at the plane a texel is at displacement `t`
        // (`SourceCamera::texel_size_at` over its value at the plane, worked out once).
        let inverse_h = c.centre_distance().map_or(0.0, |h| 1.0 / h);
        let spread = |t: f32| 1.0 + t * inverse_h;
        // Each texel's depth and slopes, worked out once (each is compared with up to
        // four neighbours), a row at a time: this runs for every texture level a client
        // receives, and whole planes of them cost more in fresh pages than in
        // arithmetic. (Empty texels join nothing: nothing is worked out for them.)
        #[derive(Clone, Copy, Default)]
        struct Texel {
            depth: f32,
            slope_a: f32,
            slope_b: f32,
        }
        let row_of = |j: usize, row: &mut Vec<Texel>| {
            row.clear();
            row.extend((j * w..(j + 1) * w).map(|k| {
                if texture.depth[k] == empty {
                    return Texel::default();
                }
                let n = decode_normal_rgb8(texture.normal[k]);
                Texel {
                    depth: depth(k),
                    slope_a: slope_along(n, a_dir, c.f),
                    slope_b: slope_along(n, b_dir, c.f),
                }
            }));
        };
        // Whether two surface texels `p` and `q`, a texel `step` apart, are joined, with
        // their slopes along that step.
        let joined = |p: Texel, q: Texel, (sp, sq): (f32, f32), step: f32| {
            // (A perspective texture's neighbouring rays part with depth: the texel's
            // side where the surface lies.)
            let step = step * spread(p.depth.max(q.depth));
            (p.depth - q.depth).abs() <= join_reach(sp.max(sq), step, quantum)
        };
        let covered = |k: usize| texture.depth[k] != empty;
        let mut right = vec![false; w * h];
        let mut down = vec![false; w * h];
        let (mut row, mut below) = (Vec::with_capacity(w), Vec::with_capacity(w));
        if h > 0 {
            row_of(0, &mut row);
        }
        for j in 0..h {
            if j + 1 < h {
                row_of(j + 1, &mut below);
            }
            for i in 0..w {
                let k = j * w + i;
                right[k] = i + 1 < w
                    && covered(k)
                    && covered(k + 1)
                    && joined(row[i], row[i + 1], (row[i].slope_a, row[i + 1].slope_a), a_len);
                down[k] = j + 1 < h
                    && covered(k)
                    && covered(k + w)
                    && joined(row[i], below[i], (row[i].slope_b, below[i].slope_b), b_len);
            }
            std::mem::swap(&mut row, &mut below);
        }
        let occupied: Vec<std::ops::Range<usize>> = (0..h)
            .map(|j| {
                let row = &texture.depth[j * w..(j + 1) * w];
                match (
                    row.iter().position(|&q| q != empty),
                    row.iter().rposition(|&q| q != empty),
                ) {
                    (Some(first), Some(last)) => first..last + 1,
                    _ => 0..0,
                }
            })
            .collect();
        let levels = WarpLevels::new(texture.depth_bits);
        let surface = SurfaceExtent::of(
            &occupied,
            (texture.depth.iter().filter(|&&q| q != empty)).map(|&q| levels.entry(q)),
        );
        let packed = (texture.albedo.iter().zip(&texture.normal).zip(&texture.depth))
            .zip(right.iter().zip(&down))
            .map(|(((&albedo, &normal), &level), (&right, &down))| {
                pack_texel(albedo, normal, levels.entry(level), right, down)
            })
            .collect();
        let outlines = row_outlines(&texture);
        Impostor {
            texture,
            right,
            down,
            packed,
            occupied,
            surface,
            faces: Faces::Both,
            outlines,
        }
    }

    /// The key of [`Impostor::outlines`] for the near texel `texel` of a step down to its
    /// right (`rightwards`) or left neighbour.
    pub fn outline_key(texel: usize, rightwards: bool) -> u32 {
        (texel as u32) << 1 | u32::from(rightwards)
    }

    /// The same impostor, showing `faces`.
    pub fn with_faces(self, faces: Faces) -> Impostor {
        Impostor { faces, ..self }
    }
}

/// [`Impostor::outlines`] of `texture`: its hidden-surface entries beside a covered
/// neighbour to the left or right, each at half a texel past the last texel its walk
/// found the deeper surface behind (its outline lies between that and the next, and
/// halfway is the middle of the guesses, as in `Job::crack_fillers`).
///
/// The bake walks every other row: each outline is also the rows' beside it, its near
/// texel there the same column or one aside (where no outline of their own is listed;
/// the same column's first, and of two rows' the row above's). Left filled, a row
/// between two outlines drew a strand of the deeper surface across the opening.
fn row_outlines(texture: &ReliefTexture) -> HashMap<u32, (Vec2, f32)> {
    let c = &texture.camera;
    let (w, h) = (c.width, c.height);
    let mut listed = Vec::new();
    for entry in &texture.hidden {
        let (di, dj) = TEXEL_SIDES[entry.side as usize];
        let (i, j) = (entry.texel % w.max(1), entry.texel / w.max(1));
        let Some(behind) = entry
            .behind(w, h)
            .filter(|_| dj == 0 && texture.is_outline(entry))
        else {
            continue;
        };
        let at = Vec2::new(behind.0 as f32 + 0.5 - 0.5 * di as f32, behind.1 as f32 + 0.5);
        let depth = c.depth_of_level(entry.depth, texture.depth_bits);
        listed.push(((i, j), di > 0, (at, depth)));
    }
    let mut outlines: HashMap<u32, (Vec2, f32)> = (listed.iter())
        .map(|&((i, j), rightwards, outline)| {
            (Impostor::outline_key((j * w + i) as usize, rightwards), outline)
        })
        .collect();
    // (The same column's copies first; of two rows', in the list's order, by texel, the
    // row above's.)
    for di in [0i32, -1, 1] {
        for (&((i, j), rightwards, (at, depth)), dj) in listed.iter().flat_map(|e| [(e, 1i32), (e, -1)]) {
            let (Some(i2), Some(j2)) = (i.checked_add_signed(di), j.checked_add_signed(dj)) else {
                continue;
            };
            if i2 < w && j2 < h {
                let moved = at + Vec2::new(di as f32, dj as f32);
                let key = Impostor::outline_key((j2 * w + i2) as usize, rightwards);
                outlines.entry(key).or_insert((moved, depth));
            }
        }
    }
    outlines
}
