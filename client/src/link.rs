//! The client's link to its server, kept alive through what a network and an operator
//! do to it: the scene uploaded again when the server has lost it (a restart, an
//! eviction from its store), and a watch on whether textures can come at all.
//!
//! # Degraded
//!
//! The link is *degraded* while the server cannot be reached or has no worker: no
//! texture can come from it then. [`Health`] says so once on stderr when it begins and
//! when it ends, and counts its seconds for the run's summary; meanwhile the requests
//! go to the in-process generator (see [`source`](crate::source)), and back to the
//! server as soon as a look at its counters finds it serving again. A look that finds
//! the server restarted (its `instance` changed) uploads the scene again at once; one
//! that cannot tell (a server that does not say) does so when it had been unreachable.
//! A look unanswered while results still come from the server finds it busy, not
//! lost: it counts as a report of saturation, not towards [`SILENT_LOOKS`].
//!
//! # Uploading again
//!
//! A request answered "no scene with hash …" finds the scene gone: [`Link::upload_again`]
//! uploads it once for every request that found it gone at the same time (they wait
//! for the one upload), and after a failed upload waits [`REUPLOAD_BACKOFF_FIRST`],
//! doubling, before trying again — a server refusing the scene is not sent it in a loop.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use relief_core::hash::ContentHash;
use relief_proto::bundle::Bundle;

use crate::manager::Arrival;
use crate::remote::Remote;
use tokio::sync::mpsc::UnboundedSender;

/// How often the link looks at the server's counters (is it there, has it a worker):
/// a server back after a restart is found within this …
pub const HEALTH_POLL: Duration = Duration::from_millis(500);

/// … and a look unanswered within this is given up; [`SILENT_LOOKS`] in a row count
/// as unreachable (a link cut without a word: HTTP/2 keepalive ends the connection
/// about then too).
pub const HEALTH_POLL_TIMEOUT: Duration = Duration::from_secs(2);

/// Looks given up in a row before the server counts as unreachable: one alone is a
/// busy server (at 64 clients on two cores, single slow answers sent every client's
/// requests to its own generator, and made the overload worse).
pub const SILENT_LOOKS: u32 = 2;

/// After a failed upload of the scene, the next waits this long, …
pub const REUPLOAD_BACKOFF_FIRST: Duration = Duration::from_millis(250);

/// … doubling each failure, up to this.
pub const REUPLOAD_BACKOFF_MAX: Duration = Duration::from_secs(8);

/// Why no texture can come from the server.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Degraded {
    /// It does not answer (down, restarting, or cut off).
    Unreachable(String),
    /// It answers, but has no worker to make textures.
    NoWorkers,
}

impl std::fmt::Display for Degraded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Degraded::Unreachable(why) => write!(f, "the server cannot be reached ({why})"),
            Degraded::NoWorkers => write!(f, "the server has no worker"),
        }
    }
}

#[derive(Debug, Default)]
struct HealthState {
    /// Since when, and why, while degraded.
    degraded: Option<(Instant, Degraded)>,
    /// Time degraded before the current episode.
    past: Duration,
}

/// Whether textures can come from the server now, and for how long they could not: a
/// cheap handle, shared by the link's tasks and whoever reports on the run.
#[derive(Debug, Clone, Default)]
pub struct Health(Arc<Mutex<HealthState>>);

impl Health {
    fn lock(&self) -> MutexGuard<'_, HealthState> {
        // (A panic elsewhere while holding it leaves plain counters: still good.)
        self.0.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The link is degraded for `why` (said once on stderr as it begins).
    pub fn degrade(&self, why: Degraded) {
        let mut state = self.lock();
        if state.degraded.is_none() {
            tracing::warn!("{why}: drawing with textures made here, or geometry, until it serves again");
            state.degraded = Some((Instant::now(), why));
        }
    }

    /// Textures can come from the server again (said once, with how long they could
    /// not); returns why they could not, if they could not until now.
    pub fn restore(&self) -> Option<Degraded> {
        let mut state = self.lock();
        let (since, why) = state.degraded.take()?;
        let lasted = since.elapsed();
        state.past += lasted;
        tracing::warn!(
            "the server serves again, after {:.1} s ({why})",
            lasted.as_secs_f64()
        );
        Some(why)
    }

    /// Why no texture can come from the server now, if none can.
    pub fn degraded(&self) -> Option<Degraded> {
        self.lock().degraded.as_ref().map(|(_, why)| why.clone())
    }

    /// Seconds degraded so far, the current episode included.
    pub fn degraded_s(&self) -> f64 {
        let state = self.lock();
        let now = state
            .degraded
            .as_ref()
            .map_or(Duration::ZERO, |(since, _)| since.elapsed());
        (state.past + now).as_secs_f64()
    }
}

/// Uploads of the scene after the first, and when the next may be tried.
#[derive(Debug)]
struct Uploads {
    /// Uploads that succeeded (after the one before the flight).
    done: u64,
    /// Failed uploads in a row, and the earliest the next may start.
    failures: u32,
    retry_at: Option<Instant>,
}

/// What every request to one server shares: the connection, the scene to upload again,
/// and the link's [`Health`].
pub struct Link {
    pub remote: Remote,
    pub bundle: Arc<Bundle>,
    /// The hash the server stored the scene under.
    pub scene_hash: ContentHash,
    pub health: Health,
    uploads: tokio::sync::Mutex<Uploads>,
    /// Looks given up in a row (see [`SILENT_LOOKS`]).
    silent_looks: AtomicU32,
    /// When a message last came from the server (see [`Link::heard`]).
    last_heard: Mutex<Option<Instant>>,
    /// The server's `instance` at the last look (0: none seen yet, or a server that
    /// does not say).
    instance: AtomicU64,
}

/// Why the scene could not be uploaded again.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UploadError {
    #[error("uploading the scene again failed: {0}")]
    Failed(String),
    #[error("uploading the scene again: backing off for {0:?} after {1} failure(s)")]
    BackingOff(Duration, u32),
    #[error("the server stored the scene again under {0}, not {1}")]
    OtherHash(ContentHash, ContentHash),
}

impl Link {
    pub fn new(remote: Remote, bundle: Arc<Bundle>, scene_hash: ContentHash) -> Arc<Link> {
        Arc::new(Link {
            remote,
            bundle,
            scene_hash,
            health: Health::default(),
            silent_looks: AtomicU32::new(0),
            last_heard: Mutex::new(None),
            instance: AtomicU64::new(0),
            uploads: tokio::sync::Mutex::new(Uploads {
                done: 0,
                failures: 0,
                retry_at: None,
            }),
        })
    }

    /// The number of uploads after the first so far: a request that finds the scene
    /// gone passes the count it saw before asking to [`Link::upload_again`].
    pub async fn uploads_done(&self) -> u64 {
        self.uploads.lock().await.done
    }

    /// Uploads the scene again unless another request did since `seen` (the count
    /// [`Link::uploads_done`] gave before the request was sent); waits for an upload in
    /// progress rather than starting a second.
    pub async fn upload_again(&self, seen: u64) -> Result<(), UploadError> {
        let mut uploads = self.uploads.lock().await;
        if uploads.done != seen {
            return Ok(());
        }
        if let Some(at) = uploads.retry_at
            && let Some(left) = at.checked_duration_since(Instant::now())
        {
            return Err(UploadError::BackingOff(left, uploads.failures));
        }
        let result = self.remote.clone().put_scene(&self.bundle).await;
        match result {
            Ok(hash) if hash == self.scene_hash => {
                uploads.done += 1;
                uploads.failures = 0;
                uploads.retry_at = None;
                tracing::info!("uploaded the scene again ({hash})");
                Ok(())
            }
            Ok(hash) => Err(UploadError::OtherHash(hash, self.scene_hash)),
            Err(status) => {
                uploads.failures += 1;
                let wait = REUPLOAD_BACKOFF_FIRST
                    .saturating_mul(1 << (uploads.failures - 1).min(16))
                    .min(REUPLOAD_BACKOFF_MAX);
                uploads.retry_at = Some(Instant::now() + wait);
                Err(UploadError::Failed(status.message().to_string()))
            }
        }
    }

    /// A message came from the server (a result on a request's stream): it is there,
    /// however slowly it answers a look.
    pub fn heard(&self) {
        *self.last_heard.lock().unwrap_or_else(|p| p.into_inner()) = Some(Instant::now());
    }

    /// Whether a message came from the server at or after `since`.
    fn heard_since(&self, since: Instant) -> bool {
        self.last_heard
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .is_some_and(|at| at >= since)
    }

    /// Looks once at the server's counters (at most [`HEALTH_POLL_TIMEOUT`]) and
    /// brings [`Link::health`] up to date: before a flight, so that its first requests
    /// go where textures can come from. Returns the wait the server foresees for a new
    /// job behind the others (`queue_wait_ms`), when it answered — and, when it did not
    /// answer in time but results came from it meanwhile, the look's own wait: a server
    /// that busy is saturated, not lost.
    pub async fn look(&self) -> Option<Duration> {
        let started = Instant::now();
        let look = tokio::time::timeout(HEALTH_POLL_TIMEOUT, self.remote.clone().stats()).await;
        // Unanswered, but results came meanwhile: the server is there, and busy. (At
        // 64 clients on two cores, such looks counted as lost sent clients to their
        // own generators, whose bakes took the workers' cores: the farm served a fifth
        // of what it served 32 clients.)
        let busy = look.is_err() && self.heard_since(started);
        let wait = match &look {
            Ok(Ok(stats)) => Some(Duration::from_millis(stats.queue_wait_ms.into())),
            _ if busy => Some(HEALTH_POLL_TIMEOUT),
            _ => None,
        };
        if look.is_ok() || busy {
            self.silent_looks.store(0, Ordering::Relaxed);
        }
        if busy {
            return wait;
        }
        match look {
            Ok(Ok(stats)) if stats.workers == 0 => self.health.degrade(Degraded::NoWorkers),
            Ok(Ok(stats)) => {
                // A server restarted has lost the scene: upload it at once rather than
                // when a request finds it gone. The server says whether it restarted;
                // one that does not say, back from being unreachable, may have. (Every
                // client uploading again after a blip sent the server the scene once
                // per client.)
                let seen = self.instance.swap(stats.instance, Ordering::Relaxed);
                let restarted = (seen != 0 && stats.instance != 0).then_some(seen != stats.instance);
                let was_unreachable = matches!(self.health.restore(), Some(Degraded::Unreachable(_)));
                if restarted.unwrap_or(was_unreachable) {
                    let done = self.uploads_done().await;
                    match self.upload_again(done).await {
                        Ok(()) => {}
                        // The next look tries again (to it, the server is still new):
                        // after a failure, once the back-off allows.
                        Err(e @ UploadError::Failed(_)) => {
                            tracing::warn!("{e}");
                            self.instance.store(seen, Ordering::Relaxed);
                        }
                        Err(e @ UploadError::BackingOff(..)) => {
                            tracing::debug!("{e}");
                            self.instance.store(seen, Ordering::Relaxed);
                        }
                        // (Not again: it would be stored under the other hash again.)
                        Err(e @ UploadError::OtherHash(..)) => tracing::warn!("{e}"),
                    }
                }
            }
            Ok(Err(status)) => self
                .health
                .degrade(Degraded::Unreachable(status.message().to_string())),
            Err(_) => {
                let silent = self.silent_looks.fetch_add(1, Ordering::Relaxed) + 1;
                if silent >= SILENT_LOOKS {
                    self.health.degrade(Degraded::Unreachable(format!(
                        "{silent} looks unanswered within {HEALTH_POLL_TIMEOUT:?} each"
                    )));
                }
            }
        }
        wait
    }

    /// [`Link::look`] every [`HEALTH_POLL`], for ever (the task serving the link's
    /// requests ends it with the run), passing the server's load on to the manager, and
    /// the look's round trip — `half` added each way, as to every exchange over the
    /// link — when the server answered it: the link's own, which no bake or queue
    /// lengthens ([`Arrival::LinkRoundTrip`]).
    pub async fn watch(self: Arc<Link>, arrivals: UnboundedSender<Arrival>, half: Duration) {
        let mut tick = tokio::time::interval(HEALTH_POLL);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tick.tick().await;
            // (The manager gone, the run is over: a server stopping with it is no news.)
            if arrivals.is_closed() {
                return;
            }
            let started = Instant::now();
            tokio::time::sleep(half).await;
            let wait = self.look().await;
            // (A look the server was too busy to answer took its whole timeout.)
            let answered = started.elapsed() < half + HEALTH_POLL_TIMEOUT;
            tokio::time::sleep(half).await;
            let Some(wait) = wait else { continue };
            if arrivals.send(Arrival::ServerLoad { wait }).is_err() {
                return;
            }
            if answered {
                let round_trip = started.elapsed();
                if arrivals.send(Arrival::LinkRoundTrip { round_trip }).is_err() {
                    return;
                }
            }
        }
    }
}
