//! Taking in the textures that arrive: decoded and made ready ([`ReadyTexture`]) once
//! per texture in a process, however many of its clients receive it.
//!
//! A client alone takes in a few textures a second, and making one ready (decoding its
//! planes, building its pyramid, finding its critical points and rim) costs it a few
//! milliseconds. But the load test runs many clients in one process, and the server
//! serves most of their requests with textures it made for another client's eye: 91 %
//! of them, at 64 clients. Each client making its own copy, the process took in about
//! 200 textures a second on the same two cores as the workers, spent a core on it, and
//! grew by 350 MB a second — the kernel's zeroing of fresh pages alone was 13 % of the
//! machine's time — and once round trips drew out, the load fed itself (see
//! `docs/load-test.md`, "Episodes at 64 clients"). Clients given one [`Intake`] share
//! what it made ready: the same texture is decoded and made ready once, and held once,
//! by every client holding it. (Clients on machines of their own share nothing; a
//! client alone pays a digest, about 0.1–0.2 ms a 256² texture.)
//!
//! A texture is known by a BLAKE3 digest of its message — every field, planes and all —
//! and the faces its object shows. What the intake remembers holds the textures
//! weakly: once no client holds one, it is gone.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::time::Instant;

use relief_core::hash::ContentHash;
use relief_proto::convert::texture_from_pb;
use relief_proto::pb;
use relief_render::impostor::Faces;

use crate::manager::{Prepared, ReadyTexture};

/// Where the clients of a process take in their textures: clone it to share it.
#[derive(Clone, Default)]
pub struct Intake {
    made: Arc<Mutex<Made>>,
}

/// The textures made ready, by digest, and how many were added since the last sweep.
#[derive(Default)]
struct Made {
    by_digest: HashMap<ContentHash, Weak<Prepared>>,
    added: usize,
}

/// Entries added between sweeps of those no client holds: the map stays within this
/// of the textures held.
const SWEEP_EVERY: usize = 256;

impl Intake {
    /// `texture` (the message `field` of a result), which reached the client at
    /// `arrived`, made ready to show `faces` — or the same texture as another client of
    /// this intake made it ready, shared. An error names what in the message is wrong.
    pub fn ready(
        &self,
        field: &str,
        texture: &pb::ReliefTexture,
        faces: Faces,
        arrived: Instant,
    ) -> Result<ReadyTexture, tonic::Status> {
        let digest = digest(texture, faces);
        let known = self
            .lock()
            .by_digest
            .get(&digest)
            .and_then(Weak::upgrade)
            .map(|prepared| ReadyTexture::shared(prepared, arrived));
        if let Some(ready) = known {
            return Ok(ready);
        }
        // (Made outside the lock: two clients given it at once may both make it; the
        // later one's is remembered.)
        let ready = ReadyTexture::arrived_at(texture_from_pb(field, texture)?, faces, arrived);
        let mut made = self.lock();
        made.by_digest.insert(digest, Arc::downgrade(ready.prepared()));
        made.added += 1;
        if made.added >= SWEEP_EVERY {
            made.by_digest.retain(|_, w| w.strong_count() > 0);
            made.added = 0;
        }
        Ok(ready)
    }

    /// Textures remembered (held by some client, or not yet swept).
    pub fn remembered(&self) -> usize {
        self.lock().by_digest.len()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Made> {
        // (Nothing in the map is left half-changed by a panic.)
        self.made.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A digest of every field of `texture`, and of `faces`.
fn digest(texture: &pb::ReliefTexture, faces: Faces) -> ContentHash {
    // (Every field by name: a field added to the message fails to build here until it
    // is added.)
    let pb::ReliefTexture {
        width,
        height,
        origin,
        a,
        b,
        f,
        depth_near,
        depth_far,
        depth_bits,
        eye,
        albedo,
        normal,
        depth,
        centre,
        encoding,
        hidden_texels,
        hidden_sides,
        hidden_inward,
        hidden_depths,
    } = texture;
    let mut hasher = blake3::Hasher::new();
    for word in [*width, *height, *depth_bits, *encoding as u32, faces as u32] {
        hasher.update(&word.to_le_bytes());
    }
    for value in [*depth_near, *depth_far] {
        hasher.update(&value.to_le_bytes());
    }
    for vector in [origin, a, b, f, eye, centre] {
        match vector {
            Some(v) => {
                hasher.update(&[1]);
                for value in [v.x, v.y, v.z] {
                    hasher.update(&value.to_le_bytes());
                }
            }
            None => {
                hasher.update(&[0]);
            }
        }
    }
    // Each plane after its length.
    for plane in [albedo, normal, depth] {
        hasher.update(&(plane.len() as u64).to_le_bytes());
        hasher.update(plane);
    }
    // And the lists of what the rim hides, each after its length.
    for list in [hidden_texels, hidden_sides, hidden_inward, hidden_depths] {
        hasher.update(&(list.len() as u64).to_le_bytes());
        for word in list {
            hasher.update(&word.to_le_bytes());
        }
    }
    ContentHash(*hasher.finalize().as_bytes())
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use relief_proto::convert::vec3_to_pb;

    use super::*;

    /// Whether `a` and `b` hold the very parts made ready once.
    fn same(a: &ReadyTexture, b: &ReadyTexture) -> bool {
        Arc::ptr_eq(a.prepared(), b.prepared())
    }

    fn texture(fill: u8) -> pb::ReliefTexture {
        pb::ReliefTexture {
            width: 2,
            height: 1,
            origin: Some(vec3_to_pb(Vec3::ZERO)),
            a: Some(vec3_to_pb(Vec3::X)),
            b: Some(vec3_to_pb(Vec3::Y)),
            f: Some(vec3_to_pb(Vec3::Z)),
            depth_near: 1.0,
            depth_far: 2.0,
            depth_bits: 8,
            eye: Some(vec3_to_pb(Vec3::new(0.5, 0.5, -3.0))),
            albedo: vec![fill; 6].into(),
            normal: vec![128; 6].into(),
            depth: vec![3, 255].into(),
            centre: None,
            encoding: 0,
            hidden_texels: vec![],
            hidden_sides: vec![],
            hidden_inward: vec![],
            hidden_depths: vec![],
        }
    }

    /// Two clients given the same texture share one made ready (each with its own
    /// arrival); a texture differing in a plane's byte, or shown with other faces, is
    /// made anew; once no client holds a texture, it is made anew too.
    #[test]
    fn the_same_texture_is_made_ready_once() {
        let intake = Intake::default();
        let (first, second) = (
            Instant::now(),
            Instant::now() + std::time::Duration::from_millis(5),
        );
        let one = intake
            .ready("t", &texture(10), Faces::Both, first)
            .expect("ready");
        let again = intake
            .ready("t", &texture(10), Faces::Both, second)
            .expect("ready");
        assert!(same(&one, &again), "the same texture shared");
        assert_eq!((one.arrived(), again.arrived()), (first, second));
        let other = intake
            .ready("t", &texture(11), Faces::Both, first)
            .expect("ready");
        assert!(!same(&other, &one), "another plane, another texture");
        let front = intake
            .ready("t", &texture(10), Faces::Front, first)
            .expect("ready");
        assert!(!same(&front, &one), "other faces, another texture");
        let kept = Arc::downgrade(one.prepared());
        drop((one, again));
        assert!(kept.upgrade().is_none(), "no client holds it");
        let anew = intake
            .ready("t", &texture(10), Faces::Both, first)
            .expect("ready");
        assert!(kept.upgrade().is_none(), "made anew, not the parts let go");
        assert!(!same(&anew, &other) && !same(&anew, &front));
        assert_eq!(intake.remembered(), 3);
    }

    /// Textures no client holds are swept from what the intake remembers.
    #[test]
    fn textures_let_go_are_swept() {
        let intake = Intake::default();
        let held = intake
            .ready("t", &texture(0), Faces::Both, Instant::now())
            .expect("ready");
        for k in 1..=SWEEP_EVERY {
            // (Each its own texture: its depth range differs.)
            let mut other = texture(0);
            other.depth_near += k as f32 * 1e-3;
            drop(
                intake
                    .ready("t", &other, Faces::Both, Instant::now())
                    .expect("ready"),
            );
            assert!(intake.remembered() <= k + 1);
        }
        // The one held, the one being made at the sweep, and those made since.
        assert!(intake.remembered() <= 3, "{} remembered", intake.remembered());
        let again = intake
            .ready("t", &texture(0), Faces::Both, Instant::now())
            .expect("ready");
        assert!(same(&again, &held));
    }

    /// A bad message is an error naming the field, remembered by nothing.
    #[test]
    fn a_bad_texture_is_an_error() {
        let intake = Intake::default();
        let mut bad = texture(10);
        bad.albedo = vec![10; 5].into();
        let e = intake
            .ready("result.texture", &bad, Faces::Both, Instant::now())
            .expect_err("bad");
        assert!(e.message().contains("result.texture"), "{}", e.message());
        assert_eq!(intake.remembered(), 0);
    }
}
