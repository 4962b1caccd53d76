//! What a texture's rim hides: the surfaces a turn of the eye uncovers beside its
//! outline ([`Hidden`]).
//!
//! Seen from the side, an animal's far legs stand hidden behind its near ones; a few
//! degrees round they step out beside them. The texture holds no texel of them and its
//! planes no hint that anything is there: the gaps the client predicts from
//! neighbouring depths (`relief_render::validity::critical`) lie between two surfaces
//! the texture shows, and beside a rim there is only sky. So the bake looks past the
//! rim. From rim texels on even rows (for a side open to the left or right) or even
//! columns (up or down) — one in two along most rims — it looks inwards, away from each
//! open side, at every [`INWARD_STRIDE`]th texel up to [`inward_reach`] over the
//! object's covered texels: it casts that texel's ray on past its own surface, through
//! the faces turned away from the rays it meets (its own surface's far side), to the
//! first face turned towards them.
//!
//! Not every step is cast. The deepest goes first, then, where it finds nothing, the
//! middle one; a step that finds a surface is followed by the next towards the rim,
//! until one finds none, and from the nearest that found it on a texel at a time, until
//! one finds none (at worst the stride that found nothing, cast again). The walk
//! records the nearest step of that run: where the hidden surface lies and how deep,
//! what the client needs to predict how far a turn brings it out (a surface found a
//! stride late is predicted to come out as much later: past the bunny's near ear, its
//! far ear 5.2 texels out where by texels it is 7.3). A rim that hides nothing (most of
//! an outline) costs one step or two (each up to [`MAX_CROSSINGS`] + 1 casts), and the
//! bake 7–17 % more, the steps texel by texel up to 5 % on that (every step of every
//! rim texel, from the rim out, cost 2–3 times the bake). So a surface that reaches
//! neither the deepest step nor the middle one (a thin one just behind the rim) is
//! missed.
//!
//! What the walk steps over is taken as the rim's own surface: a nearer surface seen
//! beside it would be a step in depth the client measures apart.
//!
//! The same walk, from a step down to a deeper surface seen past a texel, finds where
//! that surface ends behind it (`find_hidden_outlines`): what a turn shows there is
//! the sky, not the surface the pre-warp would stretch across.
//!
//! Only closed solids' orthographic textures look: a sheet's faces (leaves, two-sided:
//! [`EdgeCensus::is_sheets`](relief_core::mesh::EdgeCensus::is_sheets)) say nothing by
//! their winding of which way they look, and a perspective texture is asked only for
//! sheets.

use relief_core::relief::{DepthBits, Hidden, ReliefTexture, SourceCamera, SourceProjection, TEXEL_SIDES};

use crate::bvh::Ray;
use crate::rim::{cast_rays, open_sides};
use crate::tracer::ObjectTracer;

/// How many faces turned away from the rays a ray may pass looking for one that faces
/// them: its own surface's far side, then (on a mesh of shells, or grazing a fold) one
/// more. What lies past that many is left unknown, as if there were nothing.
pub const MAX_CROSSINGS: usize = 2;

/// Texels between the steps looked at inwards from a rim texel, and from the rim to
/// the first, before the walk goes on a texel at a time: a rim that hides nothing
/// costs one step or two whatever the reach, one that hides something a step a stride
/// and up to 4 more to find its nearest texel (the last the stride that found nothing,
/// cast again). None is cast at the rim texel itself: a
/// surface behind it that reached past it would cover its open neighbour, which would
/// then not be open.
pub const INWARD_STRIDE: u8 = 4;

/// How far in from the rim a texture looks for what it hides: a sixteenth of its
/// larger edge (16 texels of a 256² texture, 32 of a 512²; under [`INWARD_STRIDE`], so
/// no rim's walk, below 64²), and how far in from a step for where the surface past it
/// ends. A surface further in comes out only past a turn that moves it
/// that far: 8–16 pixels at half a pixel to a texel, by when the gaps' tolerance has
/// retired the texture.
pub fn inward_reach(width: u32, height: u32) -> u8 {
    (width.max(height) / 16).clamp(1, u32::from(u8::MAX)) as u8
}

/// One open side of a rim texel being walked (see the module docs).
#[derive(Clone, Copy)]
struct Walk {
    /// The rim texel.
    texel: usize,
    side: u8,
    /// The step looked at now, texels in from the rim.
    inward: u8,
    /// The middle step, looked at if the deepest finds nothing (0: none).
    middle: u8,
    /// Texels from one step to the next: [`INWARD_STRIDE`], then 1 once the strides
    /// have found the nearest of theirs.
    stride: u8,
    /// The nearest step so far that found a hidden surface, and its depth level.
    found: Option<(u8, u16)>,
}

impl Walk {
    /// The walk at `inward` texels in.
    fn at(&self, inward: u8) -> Hidden {
        Hidden {
            texel: self.texel as u32,
            side: self.side,
            inward,
            depth: 0,
        }
    }

    /// Where the walk goes once its step found `hit` (a depth level behind the rim
    /// texel's own), or `Err` with what it found once it ends.
    fn next(mut self, hit: Option<u16>) -> Result<Walk, Option<Hidden>> {
        match (hit, self.found) {
            (Some(depth), _) => {
                self.found = Some((self.inward, depth));
                match self.inward.checked_sub(self.stride).filter(|&k| k > 0) {
                    Some(inward) => Ok(Walk { inward, ..self }),
                    None => self.texel_by_texel(),
                }
            }
            (None, None) if self.middle > 0 && self.middle < self.inward => Ok(Walk {
                inward: self.middle,
                middle: 0,
                ..self
            }),
            (None, Some(_)) => self.texel_by_texel(),
            (None, None) => Err(self.hidden()),
        }
    }

    /// Once the strides end, on from the nearest they found towards the rim a texel
    /// at a time (those between it and the stride that found nothing, or the rim),
    /// until a step finds nothing.
    fn texel_by_texel(self) -> Result<Walk, Option<Hidden>> {
        match self.found {
            Some((nearest, _)) if self.stride > 1 && nearest > 1 => Ok(Walk {
                inward: nearest - 1,
                stride: 1,
                ..self
            }),
            _ => Err(self.hidden()),
        }
    }

    /// What the walk found, as the texture lists it.
    fn hidden(&self) -> Option<Hidden> {
        let (inward, depth) = self.found?;
        Some(Hidden {
            depth,
            ..self.at(inward)
        })
    }
}

/// Fills `texture.hidden` (see the module docs) for a texture of `target` made in
/// `projection`: `t_range` is the bake's own rays' search from the texture's near
/// depth; on the thread pool when `parallel`. (It runs once begun, as the rim's rays
/// do: at most a few rays a rim texel.)
pub(crate) fn find_hidden(
    texture: &mut ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    projection: SourceProjection,
    parallel: bool,
) {
    if projection != SourceProjection::Orthographic || target.object.edge_census().is_sheets() {
        return;
    }
    let camera = texture.camera;
    let (w, h) = (camera.width, camera.height);
    let empty = texture.depth_bits.empty();
    let reach = inward_reach(w, h);
    let behind = |hidden: Hidden| texture.covered_behind(&hidden);
    let mut walks: Vec<Walk> = open_sides(&texture.depth, w as usize, h as usize, empty)
        .into_iter()
        .flat_map(|(texel, open)| {
            (0..TEXEL_SIDES.len() as u8)
                .filter(move |s| open & (1 << s) != 0 && every_other(texel, w as usize, *s))
                .map(move |side| Walk {
                    texel,
                    side,
                    inward: 0,
                    middle: 0,
                    stride: INWARD_STRIDE,
                    found: None,
                })
        })
        .filter_map(|walk| {
            // The deepest step over covered texels (a gap to the sky ends the object's
            // surface there).
            let covered = (1..=reach).take_while(|&k| behind(walk.at(k)).is_some()).last()?;
            let steps = covered / INWARD_STRIDE;
            (steps > 0).then_some(Walk {
                inward: steps * INWARD_STRIDE,
                middle: steps.div_ceil(2) * INWARD_STRIDE,
                ..walk
            })
        })
        .collect();
    let mut found: Vec<Hidden> = Vec::new();
    while !walks.is_empty() {
        // (Every step a walk takes lies over covered texels: its deepest did, and
        // every one nearer the rim.)
        let (stepped, texels): (Vec<Walk>, Vec<usize>) = (walks.iter())
            .filter_map(|walk| Some((*walk, behind(walk.at(walk.inward))?)))
            .unzip();
        let hits = hidden_depths(texture, target, t_range, &texels, parallel);
        walks = Vec::new();
        for (walk, hit) in stepped.into_iter().zip(hits) {
            let hit = hit.filter(|&depth| depth > texture.depth[walk.texel]);
            match walk.next(hit) {
                Ok(onwards) => walks.push(onwards),
                Err(hidden) => found.extend(hidden),
            }
        }
    }
    found.extend(find_hidden_outlines(texture, target, t_range, parallel));
    found.sort_unstable_by_key(Hidden::key);
    texture.hidden = found;
}

/// A covered neighbour lying more than this many texels' widths deeper than a texel,
/// where the texel beyond it is nearer the neighbour again than half that, is another
/// surface seen past it: a step down (`find_hidden_outlines`). (A surface seen at 76°
/// from its normal drops 4 texels' widths a texel; one running away as steeply round a
/// tube's outline goes on dropping, and is left: of the knot's 512² texture's 1,915
/// such drops to the left or right on every other row, 217 are steps.)
pub const STEP_TEXELS: f32 = 4.0;

/// A step's drop over this: how much more the deeper surface may drop beyond the
/// neighbour for the step to count (it must flatten past it), and how far from the last
/// depth found the walk's steps may find it for it to be the same surface (half the
/// step: more, and it is another one, or the near surface's own far side).
const STEP_SHARE: i64 = 2;

/// One step down walked in from its near texel (see [`find_hidden_outlines`]).
#[derive(Clone, Copy)]
struct OutlineWalk {
    /// The near texel, and the side its deeper neighbour lies on.
    texel: usize,
    side: u8,
    /// The deepest step over the near surface's covered texels.
    covered: u8,
    /// The deeper neighbour's depth level.
    neighbour: u16,
    /// How far a step's depth level may lie from the last found for the deeper surface
    /// to go on there: the step's drop over [`STEP_SHARE`].
    within: u16,
    /// Its near texel's own ray: the step 0 that met the deeper surface, and its level
    /// (`(0, neighbour)` until that ray is cast).
    found: (u8, u16),
}

/// What a step of a walk met past its texel's own surface.
#[derive(Clone, Copy)]
enum Step {
    /// The deeper surface, at this depth level.
    Meets(u16),
    /// Nothing, the ray out of the solid in front of the deeper surface's depth: its
    /// outline lies nearer.
    Open,
    /// Something else: another surface far behind (what shows past the outline is
    /// surface, not sky), or still inside the solid where the deeper surface would be
    /// (it ends at a crease with the near one: a fin's foot on its base). The walk lists
    /// nothing.
    Lost,
}

impl OutlineWalk {
    /// What a step met (`past`) past its texel's own level `own`, the walk's last step
    /// that met the deeper surface `last`.
    fn step(&self, last: (u8, u16), past: Past, own: u16, camera: &SourceCamera, bits: DepthBits) -> Step {
        match past.facing.filter(|&q| q > own) {
            Some(q) if q.abs_diff(last.1) <= self.within => Step::Meets(q),
            Some(_) => Step::Lost,
            None => {
                let depth = camera.depth_of_level(last.1, bits) - camera.depth_near;
                if past.left.is_some_and(|t| t < depth) && !past.unknown {
                    Step::Open
                } else {
                    Step::Lost
                }
            }
        }
    }
}

/// Where a surface seen past a step down along a row ends, hidden behind the step's near
/// texel: the body of a teapot seen through its handle, parallel rays meeting it all
/// across the loop, where an eye near it looks past its outline, behind the handle,
/// into the sky. The pre-warp fills the crack a turn opens between the handle and the
/// body from the body, as if it went on; a [`Hidden`] entry of the near texel, on the
/// step's side (beside a covered neighbour, where a rim's entries lie beside an empty
/// one), tells it where the body ends (`relief_render`'s `Impostor::outlines`): `inward`
/// texels in from the near texel, the deeper surface at `depth` is the last found
/// before its outline.
///
/// From every near texel of a step to the left or right: where its own ray, cast on
/// past its surface, meets the deeper surface (about as deep as the neighbour's), the
/// walk looks in at every [`INWARD_STRIDE`]th texel up to [`inward_reach`] over the
/// near surface's covered texels, then a texel at a time from the last that met it,
/// and lists the last step that met it before one that met nothing out in the open
/// (see the walk's loop). A surface that reaches further in, or meets another far
/// behind it, lists nothing; nor do outlines in runs shorter than [`OUTLINE_RUN`].
/// Rays are cast only where they could change what is listed: from steps that could
/// take part in a kept run ([`RunRows::may_join`]), the deepest step first, and the
/// near texel's own ray only where that step could end open. (Of the rock's 512² texture's
/// 1,675 steps, 1,412 could take part in a kept run and 23 could end open: the search's
/// time fell by a fifth to a third, with the same entries.)
fn find_hidden_outlines(
    texture: &ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    parallel: bool,
) -> Vec<Hidden> {
    let camera = texture.camera;
    let (width, height) = (camera.width as usize, camera.height as usize);
    let bits = texture.depth_bits;
    let empty = bits.empty();
    let reach = inward_reach(camera.width, camera.height);
    // (An orthographic texture's depth levels are evenly spaced.)
    let jump_levels = (STEP_TEXELS * camera.a.length() / camera.depth_quantum(bits)) as i64;
    // The covered texel `inward` steps in from `texel`, away from `side`.
    let inside = |texel: usize, side: u8, inward: u8| {
        let step = Hidden {
            texel: texel as u32,
            side,
            inward,
            depth: 0,
        };
        texture.covered_behind(&step)
    };
    // Each step down: its near texel, the side, and the deeper neighbour's depth level.
    // A step the deeper surface goes on from flatter than it came (the texel beyond
    // lies nearer the neighbour than half the step): a neighbour on a surface that
    // merely runs away from the rays as steeply, round a tube's outline, goes on as
    // steeply and is left.
    let row_steps = |j: usize| {
        let row = &texture.depth[j * width..(j + 1) * width];
        let mut steps = Vec::new();
        // (Left and right: the pre-warp's row pass draws them, `Impostor::outlines`.)
        let mut step = |i: usize, side: u8, deeper: usize, beyond: usize| {
            let (q, d, b) = (row[i], row[deeper], row[beyond]);
            let drop = i64::from(d) - i64::from(q);
            let flatter = i64::from(b) - i64::from(d) < drop / STEP_SHARE;
            if drop > jump_levels && flatter && d != empty && b != empty {
                steps.push((j * width + i, side, d));
            }
        };
        for i in (0..width).filter(|&i| row[i] != empty) {
            if i >= 2 {
                step(i, 0, i - 1, i - 2);
            }
            if i + 2 < width {
                step(i, 1, i + 1, i + 2);
            }
        }
        steps
    };
    let steps: Vec<(usize, u8, u16)> = (0..height).step_by(2).flat_map(row_steps).collect();
    // Only a step that could lie in a run `in_runs` keeps, or be passed through by one,
    // can change what it lists: the others are left uncast.
    let rows = RunRows::new(steps.iter().map(|&(k, side, _)| (k, side)), width);
    let steps: Vec<(usize, u8, u16)> = (steps.iter().copied())
        .filter(|&(k, side, _)| rows.may_join(k, side))
        .collect();
    // What each of `texels`' rays meets past its own surface, and the texel's own level.
    let cast_at = |texels: &[usize]| -> Vec<(Past, u16)> {
        let pasts = cast_past(texture, target, t_range, texels, parallel);
        (pasts.into_iter())
            .zip(texels.iter().map(|&k| texture.depth[k]))
            .collect()
    };
    // Each step walked in over the near surface's covered texels, deepest first: where
    // the deeper surface goes on that far (the knot's tubes passing under one another,
    // most steps) or something else lies past it (a rock's overhangs), the walk ends
    // there, at one cast.
    let walks: Vec<OutlineWalk> = (steps.into_iter())
        .filter_map(|(texel, side, neighbour)| {
            let covered = (1..=reach)
                .take_while(|&inward| inside(texel, side, inward).is_some())
                .last()?;
            Some(OutlineWalk {
                texel,
                side,
                covered,
                neighbour,
                within: neighbour.saturating_sub(texture.depth[texel]) / STEP_SHARE as u16,
                found: (0, neighbour),
            })
        })
        .collect();
    let deepest: Vec<usize> = (walks.iter())
        .map(|walk| inside(walk.texel, walk.side, walk.covered).unwrap_or(walk.texel))
        .collect();
    // The deepest step can end open (see `OutlineWalk::step`) only where its ray left the
    // solid in front of the deepest level the near texel's own ray may meet the deeper
    // surface at: only there is that ray cast.
    let may_open = |walk: &OutlineWalk, &(past, own): &(Past, u16)| {
        let deepest_found = (0, walk.neighbour.saturating_add(walk.within));
        matches!(walk.step(deepest_found, past, own, &camera, bits), Step::Open)
    };
    let (walks, deepest): (Vec<OutlineWalk>, Vec<(Past, u16)>) = (walks.into_iter().zip(cast_at(&deepest)))
        .filter(|(walk, end)| may_open(walk, end))
        .unzip();
    // Of those, the walks whose near texel's own ray meets a surface about as deep as the
    // neighbour (within half the step), the deeper surface going on behind it, and whose
    // deepest step then ends open: the rest list nothing.
    let near: Vec<usize> = walks.iter().map(|walk| walk.texel).collect();
    let hits = hidden_depths(texture, target, t_range, &near, parallel);
    let walks: Vec<OutlineWalk> = (walks.into_iter().zip(hits).zip(deepest))
        .filter_map(|((walk, hit), (past, own))| {
            let hit = hit.filter(|hit| hit.abs_diff(walk.neighbour) <= walk.within)?;
            let walk = OutlineWalk {
                found: (0, hit),
                ..walk
            };
            matches!(walk.step(walk.found, past, own, &camera, bits), Step::Open).then_some(walk)
        })
        .collect();
    // What step `inward` of walk `n` meets, for each `(n, inward)` asked: all cast at
    // once (the walks are few and short, a batch for the pool), then read in order.
    let look = |asked: &[(usize, u8)]| -> Vec<(Past, u16)> {
        let texels: Vec<usize> = (asked.iter())
            .map(|&(n, inward)| inside(walks[n].texel, walks[n].side, inward).unwrap_or(walks[n].texel))
            .collect();
        cast_at(&texels)
    };
    // Then by strides short of it, to the first step that does not meet the deeper
    // surface (else the deepest): the stretch to look at a texel at a time, from the
    // last stride that met it.
    let strides: Vec<(usize, u8)> = (walks.iter().enumerate())
        .flat_map(|(n, walk)| {
            (INWARD_STRIDE..walk.covered)
                .step_by(INWARD_STRIDE.into())
                .map(move |inward| (n, inward))
        })
        .collect();
    let mut found: Vec<Option<(u8, u16)>> = walks.iter().map(|walk| Some(walk.found)).collect();
    let mut stretch: Vec<Option<(u8, u8)>> = vec![None; walks.len()];
    for (&(n, inward), (past, own)) in strides.iter().zip(look(&strides)) {
        let Some(last) = found[n].filter(|_| stretch[n].is_none()) else {
            continue;
        };
        match walks[n].step(last, past, own, &camera, bits) {
            Step::Meets(depth) => found[n] = Some((inward, depth)),
            Step::Open => stretch[n] = Some((last.0, inward)),
            Step::Lost => found[n] = None,
        }
    }
    for ((walk, found), stretch) in walks.iter().zip(&found).zip(&mut stretch) {
        if let (Some((last, _)), None) = (found, &stretch) {
            *stretch = Some((*last, walk.covered));
        }
    }
    // Then a texel at a time over that stretch: the last step that meets it before one
    // open.
    let texels: Vec<(usize, u8)> = (stretch.iter().enumerate())
        .filter_map(|(n, s)| Some((n, (*s)?)))
        .flat_map(|(n, (from, to))| (from + 1..to).map(move |inward| (n, inward)))
        .collect();
    let mut open: Vec<bool> = (stretch.iter().zip(&found))
        .map(|(s, f)| s.is_some() && f.is_some())
        .collect();
    let mut done = vec![false; walks.len()];
    for (&(n, inward), (past, own)) in texels.iter().zip(look(&texels)) {
        let Some(last) = found[n].filter(|_| open[n] && !done[n]) else {
            continue;
        };
        match walks[n].step(last, past, own, &camera, bits) {
            Step::Meets(depth) => found[n] = Some((inward, depth)),
            Step::Open => done[n] = true,
            Step::Lost => open[n] = false,
        }
    }
    let mut outlines: Vec<Hidden> = (walks.iter().zip(found).zip(open))
        .filter_map(|((walk, found), open)| {
            let (inward, depth) = found.filter(|_| open)?;
            Some(Hidden {
                texel: walk.texel as u32,
                side: walk.side,
                inward,
                depth,
            })
        })
        .collect();
    // (Listed as behind the near texel: deeper than its own level.)
    outlines.retain(|h| h.depth > texture.depth[h.texel as usize]);
    in_runs(outlines, width)
}

/// Outlines found from at least this many near texels in a row of the rows walked
/// (every other one) are listed; fewer are a sliver, whose few pixels are as likely a
/// crease the walk misread. (The fandisk's, one or two each, switched its textures to
/// perspective when the validity counted them; the teapot's, behind its handle, run 15
/// and more.)
pub const OUTLINE_RUN: usize = 3;

/// How far apart (texels along the row) the near texels of two outlines on consecutive
/// rows walked may lie for the second to continue the first's run ([`OUTLINE_RUN`]):
/// the step slanting up to three texels a row (the teapot's handle, 2.5 where steepest).
pub const OUTLINE_RUN_SHIFT: u32 = 6;

/// Those of `outlines` (of a texture `width` wide) in runs of [`OUTLINE_RUN`] or more.
fn in_runs(outlines: Vec<Hidden>, width: usize) -> Vec<Hidden> {
    let rows = RunRows::new(outlines.iter().map(|h| (h.texel as usize, h.side)), width);
    // How many rows walked the run through `h` goes on one way (up to the run needed),
    // each row's near texel the one nearest the last row's.
    let run_from = |h: &Hidden, down: bool| {
        let (mut row, mut column) = rows.place(h.texel as usize);
        let mut n = 0;
        while n < OUTLINE_RUN {
            let next = RunRows::walked_beside(row, down);
            match next.and_then(|r| Some((r, rows.nearest(h.side, r, column, OUTLINE_RUN_SHIFT)?))) {
                Some((r, c)) => (row, column, n) = (r, c, n + 1),
                None => break,
            }
        }
        n
    };
    (outlines.iter())
        .filter(|h| 1 + run_from(h, true) + run_from(h, false) >= OUTLINE_RUN)
        .copied()
        .collect()
}

/// The near texels of steps or outlines on each row walked, by side: what makes a run
/// ([`OUTLINE_RUN`], [`OUTLINE_RUN_SHIFT`]).
struct RunRows {
    width: usize,
    /// The near texels' columns, by side and row.
    columns: ColumnsBySideAndRow,
}

type ColumnsBySideAndRow = std::collections::HashMap<(u8, usize), Vec<usize>>;

impl RunRows {
    /// Rows between two walked (`every_other`).
    const WALKED_ROWS_APART: usize = 2;

    /// `near` (texel, side) of a texture `width` wide.
    fn new(near: impl Iterator<Item = (usize, u8)>, width: usize) -> RunRows {
        let mut columns = ColumnsBySideAndRow::default();
        for (texel, side) in near {
            columns
                .entry((side, texel / width))
                .or_default()
                .push(texel % width);
        }
        RunRows { width, columns }
    }

    /// Row and column of `texel`.
    fn place(&self, texel: usize) -> (usize, usize) {
        (texel / self.width, texel % self.width)
    }

    /// The row walked after `row` (below it, or above).
    fn walked_beside(row: usize, down: bool) -> Option<usize> {
        if down {
            row.checked_add(Self::WALKED_ROWS_APART)
        } else {
            row.checked_sub(Self::WALKED_ROWS_APART)
        }
    }

    /// The column on `row`, of a step to `side`, nearest `column` and at most `shift`
    /// from it.
    fn nearest(&self, side: u8, row: usize, column: usize, shift: u32) -> Option<usize> {
        let columns = self.columns.get(&(side, row))?;
        (columns.iter().copied())
            .filter(|c| c.abs_diff(column) <= shift as usize)
            .min_by_key(|c| c.abs_diff(column))
    }

    /// Whether `texel`'s step to `side` could lie in a run [`in_runs`] keeps: some
    /// [`OUTLINE_RUN`] rows walked through its row each hold one within
    /// [`OUTLINE_RUN_SHIFT`] × the rows walked between of its column. (Looser than a
    /// run, which moves from nearest to nearest: every member of a kept run passes.)
    fn may_run(&self, texel: usize, side: u8) -> bool {
        let (row, column) = self.place(texel);
        let holds = |offset: isize| {
            let apart = offset.unsigned_abs();
            let Some(r) = row.checked_add_signed(offset * Self::WALKED_ROWS_APART as isize) else {
                return false;
            };
            self.nearest(side, r, column, OUTLINE_RUN_SHIFT * apart as u32)
                .is_some()
        };
        let run = OUTLINE_RUN as isize;
        (0..run).any(|first| (-first..run - first).all(|offset| offset == 0 || holds(offset)))
    }

    /// Whether `texel`'s step to `side` can change what [`in_runs`] keeps: it could lie
    /// in a kept run ([`RunRows::may_run`]), or beside a step that could, where a run
    /// from there may pass it as the nearest and stop. (A step that could not lie in a
    /// kept run ends every run that reaches it: left out, it would let a run go on to
    /// a step further off and be kept where it was not.)
    fn may_join(&self, texel: usize, side: u8) -> bool {
        if self.may_run(texel, side) {
            return true;
        }
        let (row, column) = self.place(texel);
        [false, true]
            .into_iter()
            .filter_map(|down| Self::walked_beside(row, down))
            .any(|r| {
                let beside = self.columns.get(&(side, r)).map_or(&[][..], Vec::as_slice);
                (beside.iter()).any(|&c| {
                    c.abs_diff(column) <= OUTLINE_RUN_SHIFT as usize && self.may_run(r * self.width + c, side)
                })
            })
    }
}

/// What a texel's ray meets past its own surface ([`cast_past`]).
#[derive(Debug, Clone, Copy, Default)]
struct Past {
    /// The depth level of the first face that faces the rays.
    facing: Option<u16>,
    /// Where the ray last left the solid, through a face turned away (depth, from the
    /// texture's near depth), when it met none facing them after.
    left: Option<f32>,
    /// It passed [`MAX_CROSSINGS`] faces turned away and was given up.
    unknown: bool,
}

/// For each of `texels` of `texture`, the depth level of the first face behind its
/// own surface that faces the rays.
fn hidden_depths(
    texture: &ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    texels: &[usize],
    parallel: bool,
) -> Vec<Option<u16>> {
    (cast_past(texture, target, t_range, texels, parallel).into_iter())
        .map(|past| past.facing)
        .collect()
}

/// For each of `texels` of `texture`, what its ray meets cast on from just past its
/// depth (a surface within two quanta of it could not be told from it), past up to
/// [`MAX_CROSSINGS`] faces turned away.
fn cast_past(
    texture: &ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    texels: &[usize],
    parallel: bool,
) -> Vec<Past> {
    let camera = &texture.camera;
    let (w, bits) = (camera.width as usize, texture.depth_bits);
    let quantum = camera.depth_quantum(bits);
    let mesh = &target.object.mesh;
    // (Each ray beside the texel it is for, as the rays still searching shrink.)
    let mut searching: Vec<(usize, Ray)> = (texels.iter().enumerate())
        .map(|(n, &k)| {
            let (u, v) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
            let own = camera.depth_of_level(texture.depth[k], bits) - camera.depth_near;
            let ray = Ray {
                origin: camera.point(u, v, camera.depth_near),
                direction: camera.f,
                t_min: t_range.0.max(own + 2.0 * quantum),
                t_max: t_range.1,
            };
            (n, ray)
        })
        .collect();
    let mut past = vec![Past::default(); texels.len()];
    for _ in 0..=MAX_CROSSINGS {
        if searching.is_empty() {
            break;
        }
        let rays: Vec<Ray> = searching.iter().map(|(_, ray)| *ray).collect();
        let hits = cast_rays(target, &rays, parallel);
        let mut onwards = Vec::new();
        for ((n, ray), hit) in searching.iter().zip(hits) {
            let Some(hit) = hit else { continue };
            if mesh.face_normal(hit.triangle as usize).dot(camera.f) < 0.0 {
                past[*n] = Past {
                    facing: Some(camera.level_of_depth(camera.depth_near + hit.t, bits)),
                    ..Past::default()
                };
            } else {
                // A face turned away: on past it, by a quantum.
                past[*n].left = Some(hit.t);
                let ray = Ray {
                    t_min: hit.t + quantum,
                    ..*ray
                };
                onwards.push((*n, ray));
            }
        }
        searching = onwards;
    }
    for (n, _) in searching {
        past[n].unknown = true;
    }
    past
}

/// Whether rim texel `texel` (of a texture `width` wide) looks in from `side`: on even
/// rows for a side open to the left or right, on even columns up or down.
pub(crate) fn every_other(texel: usize, width: usize, side: u8) -> bool {
    let along = match TEXEL_SIDES[side as usize] {
        (0, _) => texel % width,
        _ => texel / width,
    };
    along % 2 == 0
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};
    use relief_core::mesh::Mesh;
    use relief_core::relief::DepthBits;
    use relief_core::scene::SceneObject;
    use relief_core::shading::Specular;

    use super::*;
    use crate::bake::bake;

    /// The texture from +z of `mesh`, 128² texels (a reach of 8).
    fn baked(mesh: Mesh, projection: SourceProjection) -> ReliefTexture {
        let object = SceneObject::new("boxes", mesh, DVec3::ZERO, Specular::default());
        let eye = Vec3::new(0.0, 0.0, 10.0);
        bake(
            &ObjectTracer::new(&object),
            eye,
            128,
            DepthBits::Sixteen,
            projection,
        )
        .expect("bakes")
    }

    /// What the walks of `texture` should find where `hidden_at(p)` says whether the
    /// ray through plane point `p` meets a face behind the near slab: the rule of the
    /// module docs (the deepest step over covered texels, else the middle one, then
    /// towards the rim while they find it, by strides and then by texels), written out
    /// again step by step.
    fn expected(texture: &ReliefTexture, hidden_at: impl Fn(Vec3) -> bool) -> Vec<Hidden> {
        let c = texture.camera;
        let (w, h) = (c.width as usize, c.height as usize);
        let reach = inward_reach(c.width, c.height);
        let empty = texture.depth_bits.empty();
        let mut expected = Vec::new();
        for (texel, open) in open_sides(&texture.depth, w, h, empty) {
            for side in (0..4u8).filter(|s| open & (1 << s) != 0 && every_other(texel, w, *s)) {
                let (di, dj) = TEXEL_SIDES[side as usize];
                let point = |inward: u8| {
                    let i = (texel % w) as i32 - di * i32::from(inward);
                    let j = (texel / w) as i32 - dj * i32::from(inward);
                    let inside = (0..w as i32).contains(&i) && (0..h as i32).contains(&j);
                    let covered = inside && texture.depth[j as usize * w + i as usize] != empty;
                    covered.then(|| c.point(i as f32 + 0.5, j as f32 + 0.5, c.depth_near))
                };
                let covered = (1..=reach).take_while(|&k| point(k).is_some()).count() as u8;
                let steps = covered / INWARD_STRIDE;
                let hit = |k: u8| point(k).is_some_and(&hidden_at);
                let (top, middle) = (steps * INWARD_STRIDE, steps.div_ceil(2) * INWARD_STRIDE);
                let Some(mut k) = [top, middle].into_iter().find(|&k| k > 0 && hit(k)) else {
                    continue;
                };
                while k > INWARD_STRIDE && hit(k - INWARD_STRIDE) {
                    k -= INWARD_STRIDE;
                }
                while k > 1 && hit(k - 1) {
                    k -= 1;
                }
                let p = point(k).expect("covered");
                // (The far faces at z = −1.75; rays run along −z.)
                let depth = c.level_of_depth(c.depth_near + p.z + 1.75, texture.depth_bits);
                expected.push(Hidden {
                    texel: texel as u32,
                    side,
                    inward: k,
                    depth,
                });
            }
        }
        expected
    }

    fn assert_found(texture: &ReliefTexture, expected: &[Hidden]) {
        assert_eq!(texture.hidden.len(), expected.len());
        for (got, want) in texture.hidden.iter().zip(expected) {
            assert_eq!(
                (got.texel, got.side, got.inward),
                (want.texel, want.side, want.inward)
            );
            assert!(got.depth.abs_diff(want.depth) <= 1, "{got:?} against {want:?}");
        }
        texture.check_hidden().expect("well formed");
    }

    /// A slab 2 × 2 wide hides, 2 behind it, one 1.8 wide: from every other rim
    /// texel's open side, the nearest step in whose ray meets the far slab — worked out
    /// from the texture's camera and the slab's extent — holds its front face's depth.
    /// The near slab's own back face, which every ray crosses first, is passed.
    #[test]
    fn a_rim_lists_the_surface_hidden_behind_it() {
        let mut mesh = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        mesh.append(Mesh::cuboid(Vec3::new(1.8, 1.8, 0.5), Vec3::new(0.0, 0.0, -2.0)))
            .expect("two boxes");
        let texture = baked(mesh, SourceProjection::Orthographic);
        let expected = expected(&texture, |p| p.x.abs() < 0.9 && p.y.abs() < 0.9);
        // (Of the rim's 4 × 126 texels, every other one, less the corners'.)
        assert!(
            expected.len() > 4 * 55,
            "most of the rim hides the far slab: {}",
            expected.len()
        );
        assert_found(&texture, &expected);
    }

    /// A strip hidden just behind one rim, short of the deepest step (a texture of 128²
    /// looks 8 texels in, the strip lies 2–4 texels in): found by the middle step, and
    /// its nearest texel then a texel at a time.
    #[test]
    fn a_surface_just_behind_the_rim_is_found_by_the_middle_step() {
        let mut mesh = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        mesh.append(Mesh::cuboid(
            Vec3::new(0.06, 1.0, 0.5),
            Vec3::new(-0.93, 0.0, -2.0),
        ))
        .expect("a slab and a strip");
        let texture = baked(mesh, SourceProjection::Orthographic);
        let expected = expected(&texture, |p| (-0.96..-0.9).contains(&p.x) && p.y.abs() < 0.5);
        assert!(
            expected
                .iter()
                .all(|h| h.side == 0 && (2..INWARD_STRIDE).contains(&h.inward)),
            "{expected:?}"
        );
        // (Rows of the strip's 64, every other one.)
        assert!(expected.len() >= 30, "the strip is found: {}", expected.len());
        assert_found(&texture, &expected);
    }

    /// A slab reaching to x = 1 (2 high) stands before one reaching out past its right
    /// side, whose left end lies behind it at `far_left`: the texture of the two, and
    /// from every other texel of the near slab's right rim over the far one, the last
    /// step in whose ray still meets the far slab — worked out from the camera and the
    /// slabs' extents — with the depth its ray meets it at (its front face, or the side
    /// the rays lean onto).
    fn step_outlines(near_left: f32, far_left: f32, balanced: bool) -> (ReliefTexture, Vec<Hidden>) {
        let near_width = 1.0 - near_left;
        let mut mesh = Mesh::cuboid(
            Vec3::new(near_width, 2.0, 0.5),
            Vec3::new(1.0 - near_width / 2.0, 0.0, 0.0),
        );
        let far_width = 2.5 - far_left;
        mesh.append(Mesh::cuboid(
            Vec3::new(far_width, 1.0, 0.5),
            Vec3::new(2.5 - far_width / 2.0, 0.0, -2.0),
        ))
        .expect("two boxes");
        if balanced {
            // (A speck far to the left and behind: the bounds centred on the eye's
            // line, the rays straight down z.)
            mesh.append(Mesh::cuboid(Vec3::splat(0.01), Vec3::new(-2.49, 0.0, -2.2)))
                .expect("and a speck");
        }
        let texture = baked(mesh, SourceProjection::Orthographic);
        let c = texture.camera;
        let (w, empty) = (c.width as usize, texture.depth_bits.empty());
        // Where the ray from plane point `p` meets the far slab, if it does: its front
        // face (z = −1.75) or, where the rays lean towards +x, its left side.
        let at_z = |p: Vec3, z: f32| p + c.f * ((z - p.z) / c.f.z);
        assert!(c.f.x >= 0.0, "the rays lean towards +x, or not at all: {}", c.f);
        let far_hit = |p: Vec3| {
            let (front, back) = (at_z(p, -1.75), at_z(p, -2.25));
            let hit = match front.x >= far_left {
                true => front,
                false => p + c.f * ((far_left - p.x) / c.f.x),
            };
            (back.x >= far_left && hit.y.abs() <= 0.5).then_some(hit)
        };
        let far = |p: Vec3| far_hit(p).is_some();
        let on_near = |p: Vec3| {
            let q = at_z(p, 0.25);
            (near_left..=1.0).contains(&q.x) && q.y.abs() <= 1.0
        };
        let mut expected = Vec::new();
        for (k, &q) in texture.depth.iter().enumerate() {
            let (i, j) = (k % w, k / w);
            let centre = |i: usize| c.point(i as f32 + 0.5, j as f32 + 0.5, c.depth_near);
            let deeper = texture.depth.get(k + 1).filter(|_| i + 1 < w);
            let step = deeper.is_some_and(|&d| d != empty && d > q) && !on_near(centre(i + 1));
            if !(q != empty && on_near(centre(i)) && j % 2 == 0 && step && far(centre(i + 1))) {
                continue;
            }
            let inward = (0..=i)
                .take_while(|&n| far(centre(i - n)))
                .last()
                .expect("meets it");
            let p = centre(i - inward);
            let hit = far_hit(p).expect("meets it");
            let depth = c.level_of_depth(c.depth_near + p.distance(hit), texture.depth_bits);
            expected.push(Hidden {
                texel: k as u32,
                side: 1,
                inward: inward as u8,
                depth,
            });
        }
        (texture, expected)
    }

    /// [`step_outlines`]: behind a slab 2 × 2, the far one's end 0.06 in from its edge
    /// (found by the strides, then a texel at a time); behind a bar a few texels wide,
    /// its end between the last stride and the bar's far edge (found past the strides).
    #[test]
    fn a_step_lists_where_the_surface_past_it_ends_behind_it() {
        let (texture, expected) = step_outlines(-1.0, 0.94, false);
        // (The far slab's rows, every other one, about 1 / 3.5 of 128 wide.)
        assert!(expected.len() >= 15, "{}", expected.len());
        assert!(
            (expected.iter()).all(|h| (3..INWARD_STRIDE * 2).contains(&h.inward)),
            "{expected:?}"
        );
        assert_found(&texture, &expected);
        let (texture, expected) = step_outlines(0.75, 0.8, true);
        let reach = |k: u32| {
            let (w, empty) = (texture.camera.width, texture.depth_bits.empty());
            (1..)
                .take_while(|n| k % w >= *n && texture.depth[(k - n) as usize] != empty)
                .count() as u8
        };
        assert!(expected.len() >= 15, "{}", expected.len());
        assert!(
            (expected.iter()).all(|h| h.inward > INWARD_STRIDE && reach(h.texel) % INWARD_STRIDE != 0),
            "{:?}",
            expected
                .iter()
                .map(|h| (h.inward, reach(h.texel)))
                .collect::<Vec<_>>()
        );
        // (Its left rim hides the far slab too: those entries apart.)
        let outlines = ReliefTexture {
            hidden: (texture.hidden.iter()).filter(|h| h.side == 1).copied().collect(),
            ..texture.clone()
        };
        assert_found(&outlines, &expected);
    }

    /// A convex object hides nothing behind its rim; a perspective texture, and one
    /// of sheets (the near slab left open at the back: its winding says nothing of
    /// facing), do not look.
    #[test]
    fn nothing_is_listed_where_nothing_is_hidden_or_nothing_looked() {
        let two = || {
            let mut two = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
            two.append(Mesh::cuboid(Vec3::new(1.8, 1.8, 0.5), Vec3::new(0.0, 0.0, -2.0)))
                .expect("two boxes");
            two
        };
        assert!(!baked(two(), SourceProjection::Orthographic).hidden.is_empty());
        let one = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        assert!(baked(one, SourceProjection::Orthographic).hidden.is_empty());
        assert!(baked(two(), SourceProjection::Perspective).hidden.is_empty());
        let mut open = two();
        // (The near slab's quad facing −z, its triangles 8 and 9.)
        open.triangles.drain(8..10);
        assert!(open.edge_census().is_sheets());
        assert!(baked(open, SourceProjection::Orthographic).hidden.is_empty());
    }

    /// Outlines from only the steps [`RunRows::may_join`] keeps give what [`in_runs`]
    /// keeps from all of them: the steps the outline search leaves uncast change nothing.
    /// Random steps (each texel and side once), dense enough that runs form and break,
    /// and outlines from three in four of them.
    #[test]
    fn steps_left_uncast_change_no_run() {
        let mut rng = relief_core::generators::SplitMix64::new(19);
        let width = 40;
        let (mut kept, mut uncast) = (0, 0);
        for _ in 0..500 {
            let mut steps: Vec<(usize, u8)> = (0..60)
                .map(|_| {
                    let row = 2 * (rng.next_u64() % 10) as usize;
                    let column = (rng.next_u64() % width as u64) as usize;
                    (row * width + column, (rng.next_u64() % 2) as u8)
                })
                .collect();
            steps.sort_unstable();
            steps.dedup();
            let rows = RunRows::new(steps.iter().copied(), width);
            let outlines: Vec<Hidden> = (steps.iter())
                .filter(|_| !rng.next_u64().is_multiple_of(4))
                .map(|&(texel, side)| Hidden {
                    texel: texel as u32,
                    side,
                    inward: 1,
                    depth: 1,
                })
                .collect();
            let cast: Vec<Hidden> = (outlines.iter())
                .filter(|h| rows.may_join(h.texel as usize, h.side))
                .copied()
                .collect();
            let all = in_runs(outlines, width);
            assert_eq!(in_runs(cast, width), all, "steps {steps:?}");
            kept += all.len();
            uncast += (steps.iter())
                .filter(|&&(k, side)| !rows.may_join(k, side))
                .count();
        }
        // (Both happen: runs are kept, and steps are left uncast.)
        assert!(kept > 500 && uncast > 500, "kept {kept}, uncast {uncast}");
    }
}
