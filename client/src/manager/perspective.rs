//! Which objects' textures are asked in perspective, from the eye itself, though they
//! are solids ([`projection_for`](super::policy::projection_for)).
//!
//! An orthographic texture's parallel rays see a closed surface's whole outline for
//! their direction; an eye's own rays lean out from its central one towards the
//! outline, and near an object they meet surface the parallel rays pass by — the
//! undersides of the scanned bunny's ears, seen from a little below them. The texture
//! then shows gaps at its own eye, which its critical points measure
//! ([`growth`](super::choose::growth) seen from that eye). When [`SHORT_NEEDED`] of
//! the last [`SHORT_WINDOW`] final orthographic textures an object received fall short
//! by more than [`OWN_EYE_GROWTH`], its later textures are asked in perspective, and
//! those that fell short are let go where a perspective texture can be asked from
//! their eye (not too near the object): drawn as geometry, or stale, until perspective
//! ones come. So are, from then on, its orthographic textures that fall short by as
//! much where the eye is now (a side view's, turned towards the front). A perspective
//! texture sees less of the outline as the eye turns, and is shown alone less far round
//! ([`PERSPECTIVE_LONE_TURN`](super::policy::PERSPECTIVE_LONE_TURN)).
//!
//! A texture held already that comes again, asked for again since it came, is
//! received again: a still eye that cannot show it (a warm-up's view) asks until
//! something else comes, and the server's cache answers with the same texture. One
//! bake answering two requests at once, their jobs merged, is received once.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::relief::SourceProjection;
use relief_core::scene::SceneObject;

use super::Manager;
use super::cache::Held;
use super::choose::growth;
use super::policy::{OWN_EYE_GROWTH, SHORT_NEEDED, SHORT_WINDOW, projection_for};

/// Which of the last [`SHORT_WINDOW`] final orthographic textures an object received
/// fell short of what their own eye sees: a bit each, the newest lowest. (A texture
/// received again, asked for again, is counted again: see the module docs.)
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ShortTextures(u32);

impl ShortTextures {
    /// Records the newest texture.
    fn record(&mut self, short: bool) {
        self.0 = ((self.0 << 1) | u32::from(short)) & ((1 << SHORT_WINDOW) - 1);
    }

    /// Whether [`SHORT_NEEDED`] of them fell short: the object's shape, or one view whose
    /// texture cannot be shown even there, asked for again.
    fn often(self) -> bool {
        self.0.count_ones() >= SHORT_NEEDED
    }
}

/// Whether `held` is weighed at all: an orthographic texture of a solid `object`.
pub(super) fn weighed(held: &Held, object: &SceneObject) -> bool {
    let orthographic = held.prepared.pyramid.levels[0].texture.camera.centre.is_none();
    orthographic && !object.edge_census().is_sheets()
}

/// Whether `held`, a texture of `object`, falls short where its gaps grow by `growth`
/// (screen pixels, [`growth`]): an orthographic texture of a solid, past
/// [`OWN_EYE_GROWTH`]. Weighed at its own eye as it arrives, and, once its object's
/// textures are asked in perspective, at the frame's eye ([`Manager::grades`]).
pub(super) fn falls_short(held: &Held, object: &SceneObject, growth: f32) -> bool {
    weighed(held, object) && growth > OWN_EYE_GROWTH
}

/// Whether `held`, a texture of `object`, is let go once the object's textures are
/// asked in perspective, where it serves an eye at `eye`: one that falls short, where a
/// perspective texture could be asked from there. (Where the eye is too near for a
/// perspective texture, an orthographic one is asked all the same: one that falls short
/// there is still the best to be had.)
fn replaceable(held: &Held, object: &SceneObject, eye: Vec3) -> bool {
    held.falls_short && projection_for(object, eye, true) == SourceProjection::Perspective
}

impl Manager {
    /// Weighs `held`, just arrived for object `k` (`object`, seen by `camera` in its
    /// frame) as asked from `asked_from`, at its own eye: marks it if it falls short,
    /// counts it (a final one: [`Manager::count_short`]), and returns whether to hold
    /// it: not if it falls short, `k`'s textures are asked in perspective, and one would
    /// be asked from `asked_from`. (An arrival is judged by the eye it was asked from:
    /// the server may serve one made for an eye nearby.)
    pub(super) fn weigh_own_eye(
        &mut self,
        (k, asked_from): (usize, Vec3),
        object: &SceneObject,
        held: &mut Held,
        camera: &Camera,
    ) -> bool {
        if !weighed(held, object) {
            return true;
        }
        let growth = growth(held, held.eye, camera);
        held.falls_short = falls_short(held, object, growth);
        tracing::debug!(
            object = k,
            own_eye_growth = growth,
            "orthographic texture arrived"
        );
        if held.is_final {
            self.count_short(k, object, held.falls_short);
        }
        if self.objects[k].in_perspective && replaceable(held, object, asked_from) {
            self.counters.retired.retire(held, self.objects[k].last_shown);
            return false;
        }
        true
    }

    /// Counts a final orthographic texture object `k` (`object`) received, whether it
    /// fell `short`, towards asking `k`'s textures in perspective; when they are from
    /// now on, lets go of those held that fell short where a perspective texture could
    /// be asked from their eye, and withdraws `k`'s predictions.
    pub(super) fn count_short(&mut self, k: usize, object: &SceneObject, short: bool) {
        let state = &mut self.objects[k];
        if state.in_perspective {
            return;
        }
        state.short_textures.record(short);
        if !state.short_textures.often() {
            return;
        }
        tracing::debug!(object = k, "its textures asked in perspective from now on");
        state.in_perspective = true;
        let (let_go, kept) = std::mem::take(&mut state.held)
            .into_iter()
            .partition(|h: &Held| replaceable(h, object, h.eye));
        state.held = kept;
        for h in &let_go {
            self.counters.retired.retire(h, state.last_shown);
        }
        // (Orthographic predictions still on their way would count as covering the
        // eye's future; asked again, they come in perspective where they can. A request
        // for now on its way is let come.)
        self.withdraw_predictions(k, |_| true);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two short textures among the last three switch; one alone, two three apart, or
    /// two with three others after them, do not.
    #[test]
    fn two_of_the_last_three_short_textures_switch() {
        assert_eq!(
            (SHORT_NEEDED, SHORT_WINDOW),
            (2, 3),
            "the cases below are for these"
        );
        let after = |shorts: &[bool]| {
            let mut recent = ShortTextures::default();
            for &short in shorts {
                recent.record(short);
            }
            recent.often()
        };
        assert!(!after(&[true]));
        assert!(after(&[true, true]));
        assert!(after(&[true, false, true]));
        assert!(!after(&[true, false, false, true]));
        assert!(!after(&[true, true, false, false, false]));
    }
}
