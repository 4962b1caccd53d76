//! Drawing a frame as the manager decided: each impostor redrawn as last frame's
//! sprite while Schaufler's test holds, else warped (all the frame's pre-warps at once),
//! its partner behind it; geometry rasterized; one shading pass.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::scene::{Scene, SceneObject};
use relief_render::gbuffer::GBuffer;
use relief_render::geometry::near_plane;
use relief_render::impostor::Impostor;
use relief_render::raster::rasterize;
use relief_render::validity::schaufler::sprite_still_valid;
use relief_render::warp::sprite::Sprite;
use relief_render::warp::texmap::volume_rect;
use relief_render::warp::{Prewarped, Variant};

use super::choose::Show;
use super::counters::RenderStages;
use super::policy::PARTNER_BEHIND;
use super::warp_samples::{WarpSample, WarpSampler};
use super::{Manager, Prepared};

/// One texture a frame warps: an object's shown texture, or its partner, drawn behind.
struct Warp<'a> {
    /// The object's index in the scene.
    object: usize,
    texture: &'a Arc<Prepared>,
    /// The level of its pyramid warped (one it has).
    level: usize,
    partner: bool,
}

impl Warp<'_> {
    fn impostor(&self) -> &Impostor {
        &self.texture.pyramid.levels[self.level]
    }
}

/// The last image of an impostor, kept to be redrawn while the eye stays put.
pub(super) struct Kept {
    sprite: Sprite,
    /// The camera it was drawn through.
    camera: Camera,
    /// Which textures (by their eyes) and pyramid levels it shows.
    key: ShownKey,
}

/// The textures an impostor shows, by their eyes, and their pyramid levels: the
/// first, and the partner behind it.
type ShownKey = ((Vec3, usize), Option<(Vec3, usize)>);

/// The depth factor (see [`Prewarped::behind`]) that
/// puts a partner [`PARTNER_BEHIND`] behind, for an object with `bounds` seen from `eye`.
pub(super) fn partner_depth_factor(bounds: &relief_core::bounds::Aabb, eye: Vec3) -> f32 {
    let radius = bounds.extent().length() * 0.5;
    let distance = bounds.center().distance(eye).max(radius).max(f32::MIN_POSITIVE);
    1.0 + PARTNER_BEHIND * radius / distance
}

impl Manager {
    /// From the next frame on, keeps about one in `every` successful pre-warps (within
    /// [`MAX_WARP_SAMPLES`](super::policy::MAX_WARP_SAMPLES) and
    /// [`MAX_WARP_SAMPLE_TEXELS`](super::policy::MAX_WARP_SAMPLE_TEXELS)) to be timed
    /// again ([`WarpSample`]); `every` 0 keeps none.
    pub fn sample_warps(&mut self, every: u32) {
        self.warp_samples = (every > 0).then(|| WarpSampler::new(every));
    }

    /// The pre-warps kept ([`Manager::sample_warps`]), handed over, and how many more
    /// were chosen but left out, the limits reached.
    pub fn take_warp_samples(&mut self) -> (Vec<WarpSample>, usize) {
        self.warp_samples
            .take()
            .map(|s| (s.kept, s.left_out))
            .unwrap_or_default()
    }

    /// Draws a frame as [`Manager::frame`] decided: each impostor redrawn as the
    /// sprite it was last frame while Schaufler's test holds (no warp), else warped
    /// (falling back to geometry where a warp is refused); geometry rasterized; one
    /// shading pass.
    ///
    /// The frame is drawn on a thread of rayon's pool, so the many small parallel
    /// steps inside it (a texture mapping's rows, each impostor's footprints) fork
    /// within the pool: from a thread outside it, each would wake a pool thread and
    /// sleep until it is done — at 300 impostors, about 900 such hand-overs a frame.
    pub fn render(&mut self, scene: &Scene, shows: &[Show], camera: &Camera, gbuffer: &mut GBuffer) -> Frame {
        // (Timed from here: the hand-over into the pool is the frame's.)
        let start = Instant::now();
        rayon::scope(|_| self.render_in_pool(start, scene, shows, camera, gbuffer))
    }

    fn render_in_pool(
        &mut self,
        start: Instant,
        scene: &Scene,
        shows: &[Show],
        camera: &Camera,
        gbuffer: &mut GBuffer,
    ) -> Frame {
        gbuffer.clear();
        self.sprites.resize_with(scene.objects.len(), || None);
        // Each object is tested and drawn in its own frame (see `SceneObject`).
        let locals: Vec<Camera> = scene.objects.iter().map(|o| o.local_camera(camera)).collect();
        // Which impostors are redrawn as sprites and which warped: the warps' pre-warps
        // all run at once, then everything is drawn in order.
        let keys: Vec<Option<ShownKey>> = shows
            .iter()
            .enumerate()
            .map(|(k, show)| match *show {
                Show::Impostor {
                    texture,
                    level,
                    partner,
                } => {
                    // (A `Show` from before textures arrived or were dropped names textures
                    // no longer held: drawn as geometry, or without its partner.)
                    let held = &self.objects[k].held;
                    let shown = (held.get(texture)?.eye, level);
                    Some((shown, partner.and_then(|(p, l)| Some((held.get(p)?.eye, l)))))
                }
                Show::Geometry => None,
            })
            .collect();
        let sprite_holds: Vec<bool> = keys
            .iter()
            .enumerate()
            .map(|(k, key)| match (key, &self.sprites[k]) {
                (Some(key), Some(kept)) => {
                    let o = &scene.objects[k];
                    kept.key == *key
                        && sprite_still_valid(&o.local_bounds, &o.local_camera(&kept.camera), &locals[k])
                }
                _ => false,
            })
            .collect();
        // The textures to warp: each impostor's, its partner right after it.
        let mut warps: Vec<Warp> = Vec::new();
        for (k, show) in shows.iter().enumerate() {
            if let Show::Impostor {
                texture,
                level,
                partner,
            } = *show
                && !sprite_holds[k]
            {
                let warp = |(texture, level): (usize, usize), partner: bool| {
                    let held = self.objects[k].held.get(texture)?;
                    held.prepared.pyramid.levels.get(level)?;
                    Some(Warp {
                        object: k,
                        texture: &held.prepared,
                        level,
                        partner,
                    })
                };
                let Some(shown) = warp((texture, level), false) else {
                    continue;
                };
                warps.push(shown);
                warps.extend(partner.and_then(|p| warp(p, true)));
            }
        }
        let behind = |k: usize| partner_depth_factor(&scene.objects[k].local_bounds, locals[k].eye_f32());
        // (Each timed only for the samples kept: no clock read otherwise.)
        let timed = self.warp_samples.is_some();
        let prewarps: Vec<_> = warps
            .par_iter()
            .map(|warp| {
                let k = warp.object;
                let began = timed.then(Instant::now);
                let prewarped = Prewarped::new(Variant::Interleaved, warp.impostor(), &locals[k])
                    .and_then(|p| p.in_world(scene.objects[k].depth_scale()));
                let prewarped = if warp.partner {
                    prewarped.and_then(|p| p.behind(behind(k)))
                } else {
                    prewarped
                };
                (prewarped, began.map(|b| b.elapsed()))
            })
            .collect();
        let prewarps_done = Instant::now();
        if let Some(sampler) = &mut self.warp_samples {
            for (warp, (ready, took)) in warps.iter().zip(&prewarps) {
                if let Ok(prewarped) = ready
                    && sampler.keeps(warp.texture)
                {
                    sampler.kept.push(WarpSample {
                        object: warp.object,
                        camera: locals[warp.object],
                        partner: warp.partner,
                        visited: prewarped.texels_warped(),
                        in_frame_ms: took.map_or(0.0, |t| t.as_secs_f64() * 1e3),
                        prepared: warp.texture.clone(),
                        level: warp.level,
                    });
                }
            }
        }
        let prewarps: Vec<_> = prewarps.into_iter().map(|(ready, _)| ready).collect();
        // (Only those pre-warped: an eye in or behind a texture's plane is refused first.)
        let texels_warped = (prewarps.iter())
            .map(|ready| ready.as_ref().map_or(0, |p| p.texels_warped()) as u64)
            .sum::<u64>();
        let mut prewarps = warps.into_iter().zip(prewarps).peekable();
        let mut geometry: Vec<(u32, &SceneObject)> = Vec::new();
        for (k, key) in keys.into_iter().enumerate() {
            let Some(key) = key else {
                self.sprites[k] = None;
                geometry.push((k as u32, &scene.objects[k]));
                continue;
            };
            if sprite_holds[k]
                && let Some(kept) = &self.sprites[k]
            {
                kept.sprite.draw(gbuffer);
                self.counters.sprites += 1;
                continue;
            }
            // The impostor's warp, then its partner's (whose failure only leaves out
            // what it would have filled in).
            let (mut rect, mut partner_drawn): (Option<(u32, u32, u32, u32)>, bool) = (None, false);
            while let Some((warp, ready)) = prewarps.next_if(|(warp, _)| warp.object == k) {
                let (impostor, is_partner) = (warp.impostor(), warp.partner);
                if is_partner && rect.is_none() {
                    continue;
                }
                if let Ok(prewarped) = ready {
                    let camera = &locals[k];
                    prewarped.draw(impostor, k as u32, camera, gbuffer);
                    partner_drawn |= is_partner;
                    self.counters.partners += u64::from(is_partner);
                    let r = volume_rect(camera, &impostor.texture.camera);
                    rect = Some(rect.map_or(r, |q| (q.0.min(r.0), q.1.min(r.1), q.2.max(r.2), q.3.max(r.3))));
                }
            }
            // (The sprite says what it shows: without a partner that failed to draw.)
            let key = (key.0, key.1.filter(|_| partner_drawn));
            let Some(rect) = rect else {
                self.sprites[k] = None;
                geometry.push((k as u32, &scene.objects[k]));
                continue;
            };
            self.counters.warps += 1;
            // Kept only while the view moves by less than the sprite test allows
            // per frame (or has not moved yet): else the next frame warps anyway,
            // and the copy (about a seventh of a frame's time) is wasted.
            let o = &scene.objects[k];
            if self
                .last_camera
                .is_some_and(|last| !sprite_still_valid(&o.local_bounds, &o.local_camera(&last), &locals[k]))
            {
                self.sprites[k] = None;
                continue;
            }
            self.sprites[k] = Sprite::capture_in(gbuffer, k as u32, rect).map(|sprite| Kept {
                sprite,
                camera: *camera,
                key,
            });
        }
        self.last_camera = Some(*camera);
        let impostors_done = Instant::now();
        rasterize(&geometry, camera, near_plane(scene), gbuffer);
        let geometry_done = Instant::now();
        let frame = gbuffer.shade(scene, camera);
        let ms = |from: Instant, to: Instant| (to - from).as_secs_f64() * 1e3;
        self.counters.render_stages.push(RenderStages {
            prewarp_ms: ms(start, prewarps_done),
            draw_ms: ms(prewarps_done, impostors_done),
            geometry_ms: ms(impostors_done, geometry_done),
            shade_ms: ms(geometry_done, Instant::now()),
            texels_warped,
        });
        frame
    }
}
