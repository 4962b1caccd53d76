//! Which held texture an object is shown with, and its partner: each held texture
//! graded at the eye (the critical-point gap growth, the resolution test), the nearest
//! within tolerance shown, and a texture from the far side of the eye drawn behind it
//! once the shown one leaves a band past its rim or has turned far.

use glam::{Quat, Vec3};

use relief_core::camera::Camera;
use relief_core::relief::SourceProjection;
use relief_core::scene::{Scene, SceneObject};
use relief_render::validity::schaufler::{magnification, texel_angle, volume_centre};
use relief_render::warp::params::WarpParams;

use super::Manager;
use super::around::{angle_between, similar_distance};
use super::cache::Held;
use super::perspective::falls_short;
use super::policy::{
    COARSEST_SHOWN, DEFAULT_TOLERANCE, DEFAULT_VALID_ANGLE, LEAD, LONE_BAND, LONE_TURN_CAP, LONE_UNSEEN,
    MAX_TEXEL_PIXELS, MAX_TURN, PARTNER_FROM, PARTNER_MAX_TURN, PARTNERED_BAND, PLANNING_MARGIN, PROBE_LIMIT,
    PROBE_REFINEMENTS, PROBE_START, REFINE_TEXEL, lone_max_turn,
};

/// How an object is drawn this frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Show {
    Geometry,
    /// Held texture `texture`, pyramid level `level`; and a second held texture (with
    /// its level) drawn behind it, filling what the first cannot show from this eye.
    Impostor {
        texture: usize,
        level: usize,
        partner: Option<(usize, usize)>,
    },
}

/// How an impostor was shown, for the record: the texture's turn round the object from
/// the eye and its distance, the texel size on screen, the widest gap's growth and the
/// band past its rim, and its partner's turn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShownTexture {
    /// Degrees round the object from the texture's eye to the eye.
    pub turn_deg: f32,
    /// The texture's eye's distance from the object over the eye's.
    pub distance_ratio: f32,
    /// The level drawn's texel, in the angles of pixels where it shows
    /// ([`Camera::pixel_angle_towards`](relief_core::camera::Camera::pixel_angle_towards)).
    pub texel_pixels: f32,
    /// The level drawn's texels a side, and the level (0, the texture as made; each
    /// next one half as many a side).
    pub edge: u32,
    pub level: usize,
    /// The growth of the widest gap its warp opens, pixels (the critical-point error),
    /// counted [`growth_weight`](super::policy::growth_weight) times over.
    pub growth_pixels: f32,
    /// The band past the texture's rim it cannot show alone, pixels (see
    /// [`Rim::band`](relief_render::validity::rim::Rim::band)).
    pub band_pixels: f32,
    /// Of what the eye sees face-on, the share the texture's rays never met, percent
    /// ([`NormalCensus::unseen_share`](relief_core::normals::NormalCensus::unseen_share)).
    pub unseen_percent: f32,
    /// The partner's turn from the eye, degrees, when one was drawn.
    pub partner_turn_deg: Option<f32>,
}

/// How well a held texture serves an eye.
#[derive(Debug, Clone, Copy)]
pub(super) struct Grade {
    /// Growth of the widest predicted gap, screen pixels, weighted ([`growth`]).
    pub(super) growth: f32,
    /// What it cannot show alone.
    pub(super) unshown: Unshown,
    /// Too coarse to be shown: its texels would cover more than [`COARSEST_SHOWN`]
    /// pixels (eq. 4-1).
    pub(super) too_coarse: bool,
    /// Coarser than [`REFINE_TEXEL`] pixels (shown or not) and a finer texture can be
    /// had (the edge asked for now, [`Manager::size_for`], is larger).
    pub(super) finer_available: bool,
    /// The turn past which it counts as stale shown alone, at the default tolerance
    /// ([`lone_max_turn`](super::policy::lone_max_turn) of its object and projection).
    pub(super) lone_turn: f32,
}

/// What a texture cannot show at an eye alone ([`may_show`] bounds both).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct Unshown {
    /// The band past its rim, screen pixels ([`band`]).
    pub(super) band: f32,
    /// The share of the surface the eye sees face-on that its rays never met
    /// ([`unseen`]).
    pub(super) unseen: f32,
}

impl Unshown {
    /// What `held` cannot show of `object` (about its `centre`) at `eye`.
    pub(super) fn at(held: &Held, object: &SceneObject, centre: Vec3, eye: Vec3, camera: &Camera) -> Unshown {
        Unshown {
            band: band(held, centre, eye, camera),
            unseen: unseen(held, object, eye),
        }
    }
}

/// The growth (screen pixels) of `held`'s widest predicted gap when warped to `eye`,
/// counted [`growth_weight`](super::policy::growth_weight) times over.
pub(super) fn growth(held: &Held, eye: Vec3, camera: &Camera) -> f32 {
    let prepared = &held.prepared;
    let texture = &prepared.pyramid.levels[0].texture;
    let c = &texture.camera;
    let centre = c.plane_centre();
    let middle = volume_centre(c);
    if angle_between(middle, held.eye, eye) > MAX_TURN || !similar_distance(middle, eye, held.eye) {
        return f32::INFINITY;
    }
    let Ok(params) = WarpParams::without_tables(texture, eye) else {
        return f32::INFINITY;
    };
    let focal = camera.focal_pixels();
    // (At the image plane, the nearest the texture's surface comes: where a gap looks
    // widest.)
    let pixels_per_texel =
        c.a.length().max(c.b.length()) * focal / centre.distance(eye).max(f32::MIN_POSITIVE);
    prepared.critical.worst_growth(&params, &prepared.baseline) * pixels_per_texel * prepared.growth_weight
}

/// The band (screen pixels) past `held`'s rim that it cannot show alone at `eye`, about
/// the object's `centre`.
pub(super) fn band(held: &Held, centre: Vec3, eye: Vec3, camera: &Camera) -> f32 {
    let focal = camera.focal_pixels();
    let texture = &held.prepared.pyramid.levels[0].texture;
    held.prepared.rim.band(texture, centre, eye) * focal / centre.distance(eye).max(f32::MIN_POSITIVE)
}

/// Of the surface of `object` that `eye` sees face-on, each part along the line to it,
/// the share `held`'s rays never met
/// ([`NormalCensus::unseen_share`](relief_core::normals::NormalCensus::unseen_share)):
/// what turned into view past a sharp edge, or what a near eye sees beside the object's
/// centre edge-on to the texture. 0 for leaves or sheets (two-sided: every face is seen
/// from one side or the other), and for perspective textures, whose rays part (a
/// solid's, asked where its parallel rays fall short,
/// [`projection_for`](super::policy::projection_for), is bounded by its short lone turn
/// instead, [`PERSPECTIVE_LONE_TURN`](super::policy::PERSPECTIVE_LONE_TURN)).
pub(super) fn unseen(held: &Held, object: &SceneObject, eye: Vec3) -> f32 {
    let c = &held.prepared.pyramid.levels[0].texture.camera;
    if c.centre.is_some() || object.edge_census().is_sheets() {
        return 0.0;
    }
    object.normal_census().unseen_share(&[c.f], eye)
}

/// How far round from `held`'s eye an eye may turn about `axis` through `object`'s
/// `centre`, at `distance` from it, with `held` still planned to be shown there alone:
/// the band past its rim, the surface its rays never met, and the turn (the
/// [`lone_max_turn`] of `object` in `projection`, the one of the texture to be made)
/// within the planning margin of theirs ([`may_show`]), its gaps'
/// growth within [`LEAD`] of the tolerance — either way, as a texture made ahead of the
/// eye is first seen behind its own eye ([`widest_within`]). (The band and the surface
/// come from the object's shape, much the same for a texture made nearby; the growth,
/// measured on another texture than the one to be made, is where the margin is kept.)
pub(super) fn probe_lone_reach(
    held: &Held,
    (object, projection): (&SceneObject, SourceProjection),
    centre: Vec3,
    axis: Vec3,
    distance: f32,
    camera: &Camera,
    tolerance: f32,
) -> f32 {
    let from = (held.eye - centre).normalize_or_zero() * distance;
    let lone_turn = lone_max_turn(object, projection);
    let within = |angle: f32| {
        [angle, -angle].iter().all(|&a| {
            let eye = centre + Quat::from_axis_angle(axis, a) * from;
            let unshown = Unshown::at(held, object, centre, eye, camera);
            // (The growth, dearer, only where the rim and the turn allow.)
            may_show(unshown, angle, lone_turn, false, PLANNING_MARGIN, tolerance)
                && growth(held, eye, camera) <= LEAD * tolerance
        })
    };
    widest_within(within)
}

/// The widest angle (radians) `within` holds for, probed from [`PROBE_START`] at doubling
/// angles up to [`PROBE_LIMIT`], then halved back [`PROBE_REFINEMENTS`] times (at
/// least [`PROBE_START`]).
pub(super) fn widest_within(within: impl Fn(f32) -> bool) -> f32 {
    let mut angle = PROBE_START;
    while angle < PROBE_LIMIT && within(angle * 2.0) {
        angle *= 2.0;
    }
    // Refine between `angle` (within) and twice it (not).
    let (mut lo, mut hi) = (angle, angle * 2.0);
    for _ in 0..PROBE_REFINEMENTS {
        let mid = 0.5 * (lo + hi);
        if within(mid) { lo = mid } else { hi = mid }
    }
    lo
}

/// Whether a texture leaving `unshown` (the band past its rim, the surface its rays
/// never met: [`Unshown`]) at an eye `turn` radians round from its own may be shown
/// there, `partnered` or not: alone, the band under [`LONE_BAND`], the surface under
/// [`LONE_UNSEEN`], and the turn under `lone_turn` (the texture's at the default
/// tolerance, [`lone_max_turn`](super::policy::lone_max_turn)); with a partner filling
/// the band, the band under [`PARTNERED_BAND`] (the texels inside the rim stretch as the
/// band widens) and the turn under [`MAX_TURN`], the surface unbounded (the partner,
/// from the far side of the eye, holds what turned into view; measured against both,
/// the partner would have to be chosen before the grade) — all times `margin` (1 to
/// draw; the planning margin to plan).
///
/// The bands, the surface and the turn alone are the default's: they scale with
/// `tolerance` over [`DEFAULT_TOLERANCE`] (the turn up to [`LONE_TURN_CAP`]), so the
/// one knob — and the server's load and the link, which raise it — trades these
/// predicted errors for lifetime. (With the band alone fixed, four times the tolerance
/// left the requests as many: the band, not the gaps, retired the textures; with the
/// lone turn fixed at 15°, 64 clients at twice the tolerance asked 73 % more textures,
/// living 0.53 s where they lived 1.83; uncapped, the load's factor let them live 7.3
/// s, the worst frame 2.5 dB lower.) The turn partnered is where the warp stops being
/// the object's near side, whatever the tolerance.
pub(super) fn may_show(
    unshown: Unshown,
    turn: f32,
    lone_turn: f32,
    partnered: bool,
    margin: f32,
    tolerance: f32,
) -> bool {
    let turn_limit = match partnered {
        true => MAX_TURN,
        false => (lone_turn * tolerance / DEFAULT_TOLERANCE).min(LONE_TURN_CAP),
    };
    let unseen_limit = match partnered {
        true => f32::INFINITY,
        false => margin * LONE_UNSEEN * tolerance / DEFAULT_TOLERANCE,
    };
    unshown.band <= margin * band_limit(partnered, tolerance)
        && unshown.unseen <= unseen_limit
        && turn <= margin * turn_limit
}

/// The widest band past its rim a texture may leave open, alone or `partnered`, at
/// `tolerance` ([`may_show`]).
pub(super) fn band_limit(partnered: bool, tolerance: f32) -> f32 {
    let band = if partnered { PARTNERED_BAND } else { LONE_BAND };
    band * tolerance / DEFAULT_TOLERANCE
}

/// Which of an object's held textures (graded `grades` at the eye, `turn(i)` radians
/// round the object from it) is shown: of those fine enough for the screen, the one
/// nearest the eye within `tolerance`, else the one with the least growth. (The
/// growth metric sees gaps, not the side of the object a texture from far round
/// cannot show: a sphere's growth is about 0 from anywhere.)
pub(super) fn shown_texture(
    grades: &[Grade],
    tolerance: f32,
    turn: impl Fn(usize) -> f32,
) -> Option<(usize, Grade)> {
    let tolerated = |g: &Grade| g.growth <= tolerance;
    grades
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, g)| !g.too_coarse)
        .min_by(|(i, a), (j, b)| {
            tolerated(b).cmp(&tolerated(a)).then_with(|| match tolerated(a) {
                true => turn(*i).total_cmp(&turn(*j)),
                false => a.growth.total_cmp(&b.growth),
            })
        })
}

/// The first of an object's held textures (`held`: eye and grade at `future`) that
/// covers the eye `future` (all about `centre`), as prediction plans it: within the
/// planning margin of `tolerance`, not coarser than [`REFINE_TEXEL`] with a finer one
/// to be had, and
/// within the planning margin of what may be shown alone — or with a partner there
/// ([`may_show`]), held (fine enough to be drawn there, as drawing
/// requires) or asked for (`asked`).
pub(super) fn held_covering(
    centre: Vec3,
    future: Vec3,
    held: &[(Vec3, Grade)],
    asked: &[Vec3],
    tolerance: f32,
) -> Option<usize> {
    let partnered = |shown: Vec3| {
        held_partners(centre, shown, future, held).next().is_some()
            || asked
                .iter()
                .any(|&other| can_partner(centre, shown, future, other))
    };
    held.iter().position(|&(eye, g)| {
        let turn = angle_between(centre, eye, future);
        g.growth <= PLANNING_MARGIN * tolerance
            && !g.finer_available
            && (may_show(g.unshown, turn, g.lone_turn, false, PLANNING_MARGIN, tolerance)
                || (may_show(g.unshown, turn, g.lone_turn, true, PLANNING_MARGIN, tolerance)
                    && partnered(eye)))
    })
}

/// Which of the held textures (`held`: eye and grade at `eye`) can partner one made
/// from `shown` at `eye`, all about `centre`: fine enough to be drawn there, and
/// [`can_partner`].
pub(super) fn held_partners(
    centre: Vec3,
    shown: Vec3,
    eye: Vec3,
    held: &[(Vec3, Grade)],
) -> impl Iterator<Item = usize> {
    (held.iter().enumerate())
        .filter(move |(_, (other, g))| !g.too_coarse && can_partner(centre, shown, eye, *other))
        .map(|(j, _)| j)
}

/// Whether a texture made from `other` can partner one made from `shown` at `eye`
/// (all about `centre`): on the far side of the eye, the way it has turned from
/// `shown`, within [`PARTNER_MAX_TURN`] of the eye and at a similar distance.
pub(super) fn can_partner(centre: Vec3, shown: Vec3, eye: Vec3, other: Vec3) -> bool {
    let (from, eye, other) = (shown - centre, eye - centre, other - centre);
    from.cross(eye).dot(eye.cross(other)) > 0.0
        && other.angle_between(eye) <= PARTNER_MAX_TURN
        && similar_distance(Vec3::ZERO, eye, other)
}

impl Manager {
    /// How each held texture of `object` would do warped to `eye` (in its frame, as
    /// `camera` is): the growth of its widest predicted gap (neighbours' gaps over
    /// theirs at its own eye, hidden surfaces whole), in screen pixels (`INFINITY` when
    /// it cannot be warped there), whether it is too coarse to be shown, and whether a
    /// finer one can be had (eq. 4-1) — of the edge an eye there asks for
    /// ([`Manager::size_for`]). `None` where the object costs no more drawn as geometry
    /// than that texture warped ([`cheaper_as_geometry`](super::policy::cheaper_as_geometry)).
    pub(super) fn grades(
        &self,
        scene: &Scene,
        object: usize,
        eye: Vec3,
        camera: &Camera,
    ) -> Option<Vec<Grade>> {
        let o = &scene.objects[object];
        let in_perspective = self.objects[object].in_perspective;
        let wanted = Self::warped_edge(o, eye, camera, in_perspective)?;
        let centre = o.local_bounds.center();
        let at_eye = Camera {
            eye: eye.as_dvec3(),
            ..*camera
        };
        let grade = |h: &Held| {
            let texture = &h.prepared.pyramid.levels[0].texture.camera;
            let texel = magnification(texture, &at_eye);
            let grown = growth(h, eye, camera);
            // (Once the object's textures are asked in perspective, one that falls short
            // here is not shown: perspective.rs.)
            let short_here = in_perspective && falls_short(h, o, grown);
            Grade {
                growth: if short_here { f32::INFINITY } else { grown },
                unshown: Unshown::at(h, o, centre, eye, camera),
                too_coarse: texel > COARSEST_SHOWN,
                finer_available: texel > REFINE_TEXEL && texture.width < wanted,
                lone_turn: lone_max_turn(o, texture.projection()),
            }
        };
        Some(self.objects[object].held.iter().map(grade).collect())
    }

    /// How `show` draws object `k` from `camera` (in the world): `None` for geometry (or
    /// a texture no longer held).
    pub fn describe(&self, scene: &Scene, k: usize, show: &Show, camera: &Camera) -> Option<ShownTexture> {
        let Show::Impostor {
            texture,
            level,
            partner,
        } = *show
        else {
            return None;
        };
        let held = &self.objects.get(k)?.held;
        let object = scene.objects.get(k)?;
        let (camera, centre) = (&object.local_camera(camera), object.local_bounds.center());
        let eye = camera.eye_f32();
        let turn = |i: usize| Some(angle_between(centre, held.get(i)?.eye, eye).to_degrees());
        let shown = held.get(texture)?;
        let drawn = &shown.prepared.pyramid.levels.get(level)?.texture.camera;
        Some(ShownTexture {
            turn_deg: turn(texture)?,
            distance_ratio: (shown.eye - centre).length() / (eye - centre).length(),
            texel_pixels: texel_angle(drawn, eye) / camera.pixel_angle_towards(volume_centre(drawn)),
            edge: drawn.width.max(drawn.height),
            level,
            growth_pixels: growth(shown, eye, camera),
            band_pixels: band(shown, centre, eye, camera),
            unseen_percent: 100.0 * unseen(shown, object, eye),
            partner_turn_deg: partner.and_then(|(i, _)| turn(i)),
        })
    }

    /// The angle around an object over which its newest texture stays within tolerance.
    pub(super) fn valid_angle(&self, object: usize) -> f32 {
        self.objects[object].valid_angle.unwrap_or(DEFAULT_VALID_ANGLE)
    }

    /// The texture (and its level) to draw behind object `k`'s shown texture `shown`,
    /// with `grades` at this eye: a held one on the far side of the eye, the way it has
    /// turned from `shown`'s eye, fine enough, within [`PARTNER_MAX_TURN`] of the eye
    /// and [`MAX_DISTANCE_RATIO`] of its distance — it holds what the eye has turned to
    /// see and `shown` cannot. The least growth first, then the nearest (past
    /// [`MAX_TURN`] every growth is infinite). `None` while the eye is within
    /// [`PARTNER_FROM`] of `shown`'s and `shown` may be shown alone there ([`may_show`]).
    ///
    /// Its level is the coarsest whose texels are no larger than a pixel
    /// ([`MAX_TEXEL_PIXELS`]; a shown texture's may be finer, `policy::texel_pixels`): a
    /// level coarser pre-warps a quarter of the texels but draws its own stepped,
    /// speckled outline where the shown one has nothing. The held-out teapot's frame
    /// of a texture 13° round partnered by one 8.7° round (every run at a tolerance of
    /// 11.95 px; 1 in 9 at the default) scored 24.7–24.8 dB against geometry's 29.6 so,
    /// and 26.9–27.0 with the partner at this level.
    pub(super) fn partner(
        &self,
        k: usize,
        shown: usize,
        centre: Vec3,
        camera: &Camera,
        grades: &[Grade],
    ) -> Option<(usize, usize)> {
        let held = &self.objects[k].held;
        let (from, eye) = (held[shown].eye - centre, camera.eye_f32() - centre);
        // (Wanted where the texture could not be shown alone: as `may_show` rules.)
        let (turn, g) = (from.angle_between(eye), &grades[shown]);
        if turn < PARTNER_FROM && may_show(g.unshown, turn, g.lone_turn, false, 1.0, self.tolerance()) {
            return None;
        }
        held.iter()
            .zip(grades)
            .enumerate()
            .filter_map(|(i, (h, g))| {
                let usable = i != shown
                    && !g.too_coarse
                    && can_partner(centre, held[shown].eye, camera.eye_f32(), h.eye);
                usable.then_some((i, h, g.growth, (h.eye - centre).angle_between(eye)))
            })
            .min_by(|a, b| a.2.total_cmp(&b.2).then(a.3.total_cmp(&b.3)))
            .map(|(i, h, _, _)| (i, h.prepared.pyramid.level_for(camera, MAX_TEXEL_PIXELS)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manager::policy::LONE_MAX_TURN;

    /// The texture shown among four with these growths, turns 0.7, 0.1, 0.05 and 0.3
    /// from the eye; the third (the nearest) too coarse to be shown. Tolerance 4.
    fn shown(growths: [f32; 4]) -> Option<usize> {
        let turns = [0.7, 0.1, 0.05, 0.3];
        let mut grades = growths.map(|growth| Grade {
            growth,
            unshown: Unshown::default(),
            too_coarse: false,
            finer_available: false,
            lone_turn: LONE_MAX_TURN,
        });
        grades[2].too_coarse = true;
        shown_texture(&grades, 4.0, |i| turns[i]).map(|s| s.0)
    }

    /// Prediction counts a texture 40° from the future eye as covering it only with a
    /// partner on the far side that could be drawn there: one too coarse at that eye
    /// does not count (drawing would not use it), one asked for does.
    #[test]
    fn a_partner_too_coarse_to_draw_does_not_cover_the_future() {
        let around = |degrees: f32| {
            let a = degrees.to_radians();
            Vec3::new(6.0 * a.cos(), 0.0, 6.0 * a.sin())
        };
        // (Too coarse, and a finer one to be had: not shown there either.)
        let grade = |too_coarse| Grade {
            growth: 0.0,
            unshown: Unshown::default(),
            too_coarse,
            finer_available: too_coarse,
            lone_turn: LONE_MAX_TURN,
        };
        let future = around(40.0);
        let covers = |partner_too_coarse, asked: &[Vec3]| {
            let held = [
                (around(0.0), grade(false)),
                (around(75.0), grade(partner_too_coarse)),
            ];
            held_covering(Vec3::ZERO, future, &held, asked, DEFAULT_TOLERANCE).is_some()
        };
        assert!(covers(false, &[]));
        assert!(!covers(true, &[]));
        assert!(covers(true, &[around(60.0)]));
        // Near a held texture's own eye no partner is needed.
        let near = [(around(35.0), grade(false))];
        assert!(held_covering(Vec3::ZERO, future, &near, &[], DEFAULT_TOLERANCE).is_some());
    }

    /// Alone, a texture may be shown while its rim's band stays under [`LONE_BAND`];
    /// partnered, under [`PARTNERED_BAND`]; and planning asks the same within its margin.
    #[test]
    fn the_rim_band_decides_what_may_be_shown_alone_or_partnered() {
        let turn = 10f32.to_radians();
        let between = 0.5 * (LONE_BAND + PARTNERED_BAND);
        let may = |band, turn, partnered, margin| {
            may_show(
                Unshown { band, unseen: 0.0 },
                turn,
                LONE_MAX_TURN,
                partnered,
                margin,
                DEFAULT_TOLERANCE,
            )
        };
        assert!(may(0.9 * LONE_BAND, turn, false, 1.0));
        assert!(!may(between, turn, false, 1.0));
        assert!(may(between, turn, true, 1.0));
        assert!(!may(1.1 * PARTNERED_BAND, turn, true, 1.0));
        assert!(!may(0.9 * LONE_BAND, turn, false, 0.5));
        // The turn still bounds a texture whose rim shows no band (sharp edges).
        assert!(!may(0.0, 1.1 * LONE_MAX_TURN, false, 1.0));
        assert!(!may(0.0, 1.1 * MAX_TURN, true, 1.0));
        // Twice the tolerance lets the band open twice as far, and a texture alone turn
        // twice as far (a partnered one no further).
        let twice = |band, turn, partnered| {
            may_show(
                Unshown { band, unseen: 0.0 },
                turn,
                LONE_MAX_TURN,
                partnered,
                1.0,
                2.0 * DEFAULT_TOLERANCE,
            )
        };
        assert!(twice(1.9 * LONE_BAND, turn, false));
        assert!(!twice(2.1 * LONE_BAND, turn, false));
        assert!(twice(1.9 * PARTNERED_BAND, turn, true));
        assert!(twice(0.0, 1.9 * LONE_MAX_TURN, false));
        assert!(!twice(0.0, 2.1 * LONE_MAX_TURN, false));
        assert!(!twice(0.0, 1.1 * MAX_TURN, true));
        // Alone, never past the cap.
        let tenfold = |turn| {
            may_show(
                Unshown::default(),
                turn,
                LONE_MAX_TURN,
                false,
                1.0,
                10.0 * DEFAULT_TOLERANCE,
            )
        };
        assert!(tenfold(0.9 * LONE_TURN_CAP) && !tenfold(1.1 * LONE_TURN_CAP));
    }

    /// Alone, a texture may be shown while the surface turned into view that its rays
    /// never met stays under [`LONE_UNSEEN`] of what the eye sees, the limit scaling
    /// with the tolerance; partnered, the partner holds it.
    #[test]
    fn the_surface_its_rays_never_met_decides_too() {
        let turn = 5f32.to_radians();
        let may = |unseen, partnered, tolerance| {
            let unshown = Unshown { band: 0.0, unseen };
            may_show(unshown, turn, LONE_MAX_TURN, partnered, 1.0, tolerance)
        };
        assert!(may(0.9 * LONE_UNSEEN, false, DEFAULT_TOLERANCE));
        assert!(!may(1.1 * LONE_UNSEEN, false, DEFAULT_TOLERANCE));
        assert!(may(1.0, true, DEFAULT_TOLERANCE));
        assert!(may(1.9 * LONE_UNSEEN, false, 2.0 * DEFAULT_TOLERANCE));
        assert!(!may(2.1 * LONE_UNSEEN, false, 2.0 * DEFAULT_TOLERANCE));
    }

    #[test]
    fn the_texture_shown_is_the_nearest_within_tolerance_else_the_least_grown() {
        // 1 is nearer than 0, whose growth is less (2 is nearer still, but too coarse).
        assert_eq!(shown([0.0, 2.0, 0.0, 9.0]), Some(1));
        // Only 3 within tolerance, though farther than 1.
        assert_eq!(shown([7.0, 6.0, 0.0, 3.0]), Some(3));
        // None within: the least grown, wherever it is.
        assert_eq!(shown([5.0, 8.0, 0.0, f32::INFINITY]), Some(0));
        // Only a too coarse one: none.
        let coarse = Grade {
            growth: 0.0,
            unshown: Unshown::default(),
            too_coarse: true,
            finer_available: false,
            lone_turn: LONE_MAX_TURN,
        };
        assert!(shown_texture(&[coarse], 4.0, |_| 0.0).is_none());
    }
}
