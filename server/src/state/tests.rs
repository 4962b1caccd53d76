//! The scheduler's rules, tested on the plain state (no network).

use super::*;
use glam::Vec3;
use relief_core::bounds::Aabb;
use relief_core::hash::ContentHash;
use relief_core::relief::{DepthBits, SourceProjection};
use tokio::sync::mpsc::unbounded_channel;

/// The client that uploaded the scene and asks for its textures.
const OWNER: &str = "client-1";

fn state_with_scene() -> (State, ContentHash) {
    let mut s = State::new(Limits {
        cache_bytes: 1 << 20,
        lease: Duration::from_secs(5),
        max_waiting: 100,
        max_waiting_per_client: 100,
        scene_store_bytes: 1 << 20,
        job_progress: Duration::from_secs(30),
        job_timeout: Duration::from_secs(60),
    });
    let hash = ContentHash([7; 32]);
    let bounds = Aabb {
        min: Vec3::splat(-1.0),
        max: Vec3::splat(1.0),
    };
    // Two placements of one mesh, and another mesh.
    let placed = |name: &str, mesh: u8| {
        let object = StoredObject {
            bounds,
            mesh: ContentHash([mesh; 32]),
        };
        (name.to_string(), object)
    };
    s.add_scene(
        hash,
        StoredScene {
            encoded: Arc::new(vec![]),
            objects: [placed("ball", 1), placed("ball.2", 1), placed("cube", 2)]
                .into_iter()
                .collect(),
        },
        &OWNER.into(),
    )
    .unwrap();
    (s, hash)
}

/// Placements of one mesh share textures: a request from the same eye (in the
/// object's frame) for another placement joins the job queued for the first (the
/// cache is keyed alike); the same eye on another mesh gets a job of its own.
#[test]
fn placements_of_one_mesh_share_jobs() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let eye = Vec3::new(1.0, 0.0, 5.0);
    let of = |id: u64, object: &str| Request {
        object: object.into(),
        ..request(hash, id, eye, Urgency::Now)
    };
    s.admit(&of(1, "ball"), OWNER, tx.clone()).unwrap();
    s.admit(&of(2, "ball.2"), OWNER, tx.clone()).unwrap();
    assert_eq!(s.counters.merged, 1, "the second placement joins the first's job");
    s.admit(&of(3, "cube"), OWNER, tx.clone()).unwrap();
    assert_eq!(s.counters.merged, 1, "another mesh's request gets its own job");
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 2, 1, wtx);
    s.dispatch();
    let jobs: Vec<pb::Job> = std::iter::from_fn(|| next_job(&mut wrx)).collect();
    assert_eq!(jobs.len(), 2, "one job a mesh");
}

fn request(scene: ContentHash, id: u64, eye: Vec3, urgency: Urgency) -> Request {
    Request {
        scene,
        object: "ball".into(),
        eye,
        size: 128,
        depth_bits: DepthBits::Eight,
        urgency,
        client_id: "c".into(),
        request_id: id,
        progressive: false,
        projection: SourceProjection::Orthographic,
        serve_within: 0.0,
        reads_planes: Default::default(),
    }
}

/// Admits request `id` of client "c" for `hash`'s ball, needed now, from
/// `(x, 0, 5)`.
fn admit_now(s: &mut State, hash: ContentHash, id: u64, x: f32, results: ResultSender) {
    s.admit(
        &request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Now),
        OWNER,
        results,
    )
    .unwrap();
}

fn next_job(
    rx: &mut tokio::sync::mpsc::UnboundedReceiver<Result<pb::ServerMessage, Status>>,
) -> Option<pb::Job> {
    match rx.try_recv().ok()?.ok()?.kind? {
        pb::server_message::Kind::Job(j) => Some(j),
        pb::server_message::Kind::Cancel(_) => None,
    }
}

/// The milliseconds a refusal for saturation says (its metadata).
fn saturated_ms(refused: &Status) -> u64 {
    refused
        .metadata()
        .get(relief_proto::SATURATED_METADATA)
        .unwrap()
        .to_str()
        .unwrap()
        .parse()
        .unwrap()
}

/// A state with one worker of one slot, busy on a job needed now: what is admitted
/// next waits. Returns the worker's end of its session and the running job.
fn one_slot_busy() -> (
    State,
    ContentHash,
    tokio::sync::mpsc::UnboundedReceiver<Result<pb::ServerMessage, Status>>,
    pb::Job,
) {
    let (mut s, hash) = state_with_scene();
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 0.5, tx);
    s.dispatch();
    let running = next_job(&mut wrx).unwrap();
    (s, hash, wrx, running)
}

/// `late` passes (the clock the deadlines count from, moved back), and the busy slot
/// of [`one_slot_busy`] frees.
fn later_the_slot_frees(s: &mut State, running: &pb::Job, late: Duration) {
    s.epoch -= late;
    s.result(running.job_id, pb::ReliefTexture::default(), true, 10);
    s.dispatch();
}

#[test]
fn now_before_predicted_nearest_deadline_first_and_merging() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let eye = |x: f32| Vec3::new(x, 0.0, 5.0);
    s.admit(
        &request(hash, 1, eye(1.0), Urgency::Predicted { in_ms: 900 }),
        OWNER,
        tx.clone(),
    )
    .unwrap();
    s.admit(
        &request(hash, 2, eye(2.0), Urgency::Predicted { in_ms: 100 }),
        OWNER,
        tx.clone(),
    )
    .unwrap();
    s.admit(&request(hash, 3, eye(3.0), Urgency::Now), OWNER, tx.clone())
        .unwrap();
    // Same texture as request 2: merged.
    s.admit(
        &request(hash, 4, eye(2.0), Urgency::Predicted { in_ms: 50 }),
        OWNER,
        tx.clone(),
    )
    .unwrap();
    assert_eq!(s.counters.merged, 1);
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 3, 1, wtx);
    s.dispatch();
    let order: Vec<f32> = std::iter::from_fn(|| next_job(&mut wrx))
        .map(|j| j.eye.unwrap().x)
        .collect();
    assert_eq!(order, vec![3.0, 2.0, 1.0]);
}

/// One texture serves every request at its view for no more depth bits and at
/// least half its edge: smaller requests join a bigger job, queued or running, and
/// hit a bigger cached texture; a bigger one, one with more depth bits, or one far
/// smaller gets a job of its own.
#[test]
fn a_bigger_texture_serves_smaller_requests() {
    let (mut s, hash) = state_with_scene();
    let (tx, mut rx) = unbounded_channel();
    let sized = |id: u64, size: u32, depth_bits: DepthBits| Request {
        size,
        depth_bits,
        ..request(hash, id, Vec3::new(1.0, 0.0, 5.0), Urgency::Now)
    };
    s.admit(&sized(1, 64, DepthBits::Sixteen), OWNER, tx.clone())
        .unwrap();
    s.admit(&sized(2, 32, DepthBits::Eight), OWNER, tx.clone())
        .unwrap();
    s.admit(&sized(3, 128, DepthBits::Eight), OWNER, tx.clone())
        .unwrap();
    assert_eq!((s.counters.merged, s.stats().queue_now), (1, 2));
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let job = next_job(&mut wrx).unwrap();
    assert_eq!((job.size, job.depth_bits), (64, 16));
    // While it runs, a smaller request joins it.
    s.admit(&sized(4, 32, DepthBits::Eight), OWNER, tx.clone())
        .unwrap();
    assert_eq!(s.counters.merged, 2);
    s.result(job.job_id, pb::ReliefTexture::default(), true, 1);
    let mut served: Vec<u64> = std::iter::from_fn(|| rx.try_recv().ok())
        .map(|r| r.unwrap().request_id)
        .collect();
    served.sort();
    assert_eq!(served, vec![1, 2, 4]);
    // Now cached: a smaller request is a hit, one with more depth bits is not.
    assert!(matches!(
        s.admit(&sized(5, 64, DepthBits::Eight), OWNER, tx.clone()),
        Ok(Admission::Cached(_))
    ));
    s.admit(&sized(6, 128, DepthBits::Sixteen), OWNER, tx.clone())
        .unwrap();
    assert_eq!(s.counters.cache_hits, 1);
    assert_eq!((s.counters.merged, s.stats().queue_now), (2, 2));
    // Nothing more than twice its edge serves a request: 16² gets a job of its own.
    s.admit(&sized(7, 16, DepthBits::Eight), OWNER, tx.clone())
        .unwrap();
    assert_eq!(s.counters.cache_hits, 1);
    assert_eq!((s.counters.merged, s.stats().queue_now), (2, 3));
}

/// A request with a `serve_within` is served by the texture made for the
/// nearest eye within it — a job queued for another request, or a cached texture —
/// and gets a job of its own when none is that near; a request without one only by
/// its own eye.
#[test]
fn the_nearest_eye_within_serve_within_serves_a_request() {
    let (mut s, hash) = state_with_scene();
    let (tx, mut rx) = unbounded_channel();
    // From (x, 0, 5), about 5 from the ball's centre: a serve_within of 0.05 takes in
    // eyes 0.25 or so away.
    let ask = |id: u64, x: f32, serve_within: f32| Request {
        serve_within,
        ..request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Now)
    };
    s.admit(&ask(1, 0.0, 0.0), OWNER, tx.clone()).unwrap();
    s.admit(&ask(2, 0.2, 0.05), OWNER, tx.clone()).unwrap();
    assert_eq!((s.counters.merged, s.counters.served_nearby), (1, 1));
    s.admit(&ask(3, 0.6, 0.05), OWNER, tx.clone()).unwrap();
    s.admit(&ask(4, 0.2, 0.0), OWNER, tx.clone()).unwrap();
    assert_eq!(s.counters.merged, 1, "0.6 is too far; 0.2 asked exactly");
    // Both 0.6 and 0.2 are jobs now, and 0.6 is nearer.
    s.admit(&ask(5, 0.5, 0.05), OWNER, tx.clone()).unwrap();
    assert_eq!((s.counters.merged, s.counters.served_nearby), (2, 2));
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 3, 1, wtx);
    s.dispatch();
    // Each job's texture says which eye it was made for in its width (tenths of x).
    for job in std::iter::from_fn(|| next_job(&mut wrx)) {
        let texture = pb::ReliefTexture {
            width: (job.eye.unwrap().x * 10.0).round() as u32,
            albedo: vec![0; 100].into(),
            ..Default::default()
        };
        s.result(job.job_id, texture, true, 1);
    }
    let mut served: Vec<(u64, u32)> = std::iter::from_fn(|| rx.try_recv().ok())
        .map(|r| r.unwrap())
        .map(|r| (r.request_id, r.texture.unwrap().width))
        .collect();
    served.sort();
    assert_eq!(served, vec![(1, 0), (2, 0), (3, 6), (4, 2), (5, 6)]);
    // Cached: 0.12 is nearest 0.2; 0.38 is too far from all three at 0.03, and
    // nearest 0.2 at 0.05.
    let cached_width = |s: &mut State, id: u64, x: f32, serve_within: f32| match s.admit(
        &ask(id, x, serve_within),
        OWNER,
        tx.clone(),
    ) {
        Ok(Admission::Cached(t)) => Some(t.width),
        _ => None,
    };
    assert_eq!(cached_width(&mut s, 6, 0.12, 0.05), Some(2));
    assert_eq!(cached_width(&mut s, 7, 0.38, 0.03), None);
    assert_eq!(cached_width(&mut s, 8, 0.38, 0.05), Some(2));
    assert_eq!(cached_width(&mut s, 9, 0.6, 0.0), Some(6), "its own eye");
    assert_eq!(cached_width(&mut s, 10, 0.61, 0.0), None);
    assert_eq!((s.counters.cache_hits, s.counters.served_nearby), (3, 4));
}

/// The cache keeps at most `SUBJECT_SCAN` textures of one subject (each request
/// looks through them), dropping the subject's least recently used.
#[test]
fn the_cache_keeps_a_bounded_number_of_one_subjects_textures() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    let ask = |id: u64| request(hash, id, Vec3::new(id as f32 * 1e-3, 0.0, 5.0), Urgency::Now);
    let extra = 5;
    for id in 1..=(jobs::SUBJECT_SCAN + extra) as u64 {
        s.admit(&ask(id), OWNER, tx.clone()).unwrap();
        s.dispatch();
        let job = next_job(&mut wrx).unwrap();
        let texture = pb::ReliefTexture {
            albedo: vec![0; 10].into(),
            ..Default::default()
        };
        s.result(job.job_id, texture, true, 1);
    }
    assert_eq!(s.stats().cache_bytes, 10 * jobs::SUBJECT_SCAN as u64);
    let hit = |s: &mut State, id: u64| {
        let again = Request {
            request_id: 10_000 + id,
            ..ask(id)
        };
        matches!(s.admit(&again, OWNER, tx.clone()), Ok(Admission::Cached(_)))
    };
    assert!(!hit(&mut s, 1), "the oldest went");
    assert!(hit(&mut s, extra as u64 + 1), "the oldest kept is there");
}

/// The cache keeps within its bytes by dropping the least recently used texture:
/// a hit counts as a use.
#[test]
fn the_cache_drops_the_least_recently_used_texture() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    // 300 kB each: three fit in the 1 MiB cache, four do not.
    let texture = || pb::ReliefTexture {
        albedo: vec![0; 300_000].into(),
        ..Default::default()
    };
    let mut id = 0;
    let mut ask = |s: &mut State, x: f32| {
        id += 1;
        s.admit(
            &request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Now),
            OWNER,
            tx.clone(),
        )
        .unwrap()
    };
    for x in [1.0, 2.0, 3.0] {
        ask(&mut s, x);
        s.dispatch();
        let job = next_job(&mut wrx).unwrap();
        s.result(job.job_id, texture(), true, 1);
    }
    assert_eq!(s.stats().cache_bytes, 900_000);
    // Eye 1 used again: eye 2 is now the least recent.
    assert!(matches!(ask(&mut s, 1.0), Admission::Cached(_)));
    ask(&mut s, 4.0);
    s.dispatch();
    let job = next_job(&mut wrx).unwrap();
    s.result(job.job_id, texture(), true, 1);
    assert_eq!(s.stats().cache_bytes, 900_000);
    for x in [1.0, 3.0, 4.0] {
        assert!(matches!(ask(&mut s, x), Admission::Cached(_)), "eye {x}");
    }
    assert!(!matches!(ask(&mut s, 2.0), Admission::Cached(_)));
    assert_eq!(s.counters.cache_hits, 4);
}

#[test]
fn a_stream_withdraws_only_its_own_request() {
    let (mut s, hash) = state_with_scene();
    let (mine, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 7, 0.0, mine.clone());
    // Another stream that used the same id (answered from the cache, say).
    let (other, _other_rx) = unbounded_channel();
    assert!(!s.withdraw_own("c", 7, &other));
    assert_eq!(s.stats().queue_now, 1);
    assert!(s.withdraw_own("c", 7, &mine));
    assert_eq!(s.stats().queue_now, 0);
}

/// Past the job timeout a queued job (no worker) and a running one (a worker that
/// never finishes) both end in DEADLINE_EXCEEDED, the running one cancelled on its
/// worker; a job within the timeout is left alone.
#[test]
fn jobs_past_the_timeout_end_in_an_error() {
    let (mut s, hash) = state_with_scene();
    let (tx1, mut rx1) = unbounded_channel();
    let (tx2, mut rx2) = unbounded_channel();
    admit_now(&mut s, hash, 1, 0.0, tx1);
    admit_now(&mut s, hash, 2, 1.0, tx2);
    let (wtx, mut wrx) = unbounded_channel();
    let w = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let running = next_job(&mut wrx).unwrap();
    s.expire_jobs();
    assert_eq!(s.stats().jobs_timed_out, 0);
    s.limits.job_timeout = Duration::ZERO;
    s.expire_jobs();
    for rx in [&mut rx1, &mut rx2] {
        let status = rx.try_recv().unwrap().unwrap_err();
        assert_eq!(status.code(), tonic::Code::DeadlineExceeded, "{status:?}");
    }
    match wrx.try_recv().unwrap().unwrap().kind.unwrap() {
        pb::server_message::Kind::Cancel(c) => assert_eq!(c.job_id, running.job_id),
        other => panic!("expected a cancel, got {other:?}"),
    }
    let stats = s.stats();
    assert_eq!(
        (stats.jobs_timed_out, stats.queue_now, stats.jobs_in_flight),
        (2, 0, 0)
    );
    // Each request has the whole timeout: one merged into an old job outlives the
    // first, and the job goes on for it. (The worker has answered for the first.)
    s.released(w, running.job_id);
    s.limits.job_timeout = Duration::from_millis(100);
    let eye = Vec3::new(2.0, 0.0, 5.0);
    let (tx3, mut rx3) = unbounded_channel();
    let (tx4, mut rx4) = unbounded_channel();
    s.admit(&request(hash, 3, eye, Urgency::Now), OWNER, tx3).unwrap();
    s.dispatch();
    std::thread::sleep(Duration::from_millis(150));
    // Judged 60 ms after the second arrived (and so at least 210 ms after the first),
    // however long this thread waits between the lines.
    let before_second = Instant::now();
    s.admit(&request(hash, 4, eye, Urgency::Now), OWNER, tx4).unwrap();
    assert_eq!(s.stats().merged, 1);
    s.expire_jobs_at(before_second + Duration::from_millis(60));
    assert_eq!(
        rx3.try_recv().unwrap().unwrap_err().code(),
        tonic::Code::DeadlineExceeded
    );
    assert!(rx4.try_recv().is_err(), "the later request is still waiting");
    assert_eq!(s.stats().jobs_in_flight, 1);
}

/// A latency on a bucket's bound counts in that bucket; above the last, in the
/// extra one.
#[test]
fn the_latency_histogram_counts_bounds_in_their_bucket() {
    let (mut s, _) = state_with_scene();
    for ms in [0.5, 1.0, 1.5, 5000.0, 5000.5] {
        s.latencies_push(ms);
    }
    let counts = s.stats().latency_counts;
    assert_eq!(counts.len(), LATENCY_BUCKETS_MS.len() + 1);
    assert_eq!((counts[0], counts[1], counts[11], counts[12]), (2, 1, 1, 1));
    assert_eq!(counts.iter().sum::<u64>(), 5);
}

/// A cancelled job keeps its worker's slot until the worker answers for it: a
/// worker that hangs is not handed the next job.
#[test]
fn a_cancelled_job_holds_its_slot_until_the_worker_answers() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 0.0, tx.clone());
    let (wtx, mut wrx) = unbounded_channel();
    let w = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let first = next_job(&mut wrx).unwrap();
    assert_eq!(s.withdraw("c", &[1]), 1);
    admit_now(&mut s, hash, 2, 1.0, tx);
    s.dispatch();
    assert!(matches!(
        wrx.try_recv().unwrap().unwrap().kind,
        Some(pb::server_message::Kind::Cancel(_))
    ));
    assert!(
        wrx.try_recv().is_err(),
        "a job went to a worker still on a cancelled one"
    );
    assert_eq!(s.stats().queue_now, 1);
    s.released(w, first.job_id);
    s.dispatch();
    assert!(next_job(&mut wrx).is_some());
}

#[test]
fn withdrawal_cancels_queued_and_running_jobs() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 0.0, tx.clone());
    admit_now(&mut s, hash, 2, 1.0, tx.clone());
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let running = next_job(&mut wrx).unwrap();
    assert_eq!(s.withdraw("c", &[1, 2, 99]), 2);
    // The running one is cancelled on the worker; nothing is left queued.
    match wrx.try_recv().unwrap().unwrap().kind.unwrap() {
        pb::server_message::Kind::Cancel(c) => assert_eq!(c.job_id, running.job_id),
        other => panic!("expected a cancel, got {other:?}"),
    }
    assert_eq!(s.stats().queue_now, 0);
    assert_eq!(s.stats().jobs_in_flight, 0);
}

#[test]
fn a_vanished_workers_jobs_are_requeued_and_bad_requests_refused() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 0.0, tx.clone());
    let (wtx, _wrx) = unbounded_channel();
    let w = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    assert_eq!(s.stats().jobs_in_flight, 1);
    s.remove_worker(w);
    assert_eq!((s.stats().queue_now, s.counters.requeued), (1, 1));
    let inside = s
        .admit(&request(hash, 2, Vec3::ZERO, Urgency::Now), OWNER, tx.clone())
        .unwrap_err();
    assert_eq!(inside.code(), tonic::Code::FailedPrecondition);
    let mut unknown = request(hash, 3, Vec3::new(0.0, 0.0, 5.0), Urgency::Now);
    unknown.object = "cone".into();
    assert_eq!(
        s.admit(&unknown, OWNER, tx.clone()).unwrap_err().code(),
        tonic::Code::InvalidArgument
    );
    unknown.scene = ContentHash([1; 32]);
    assert_eq!(
        s.admit(&unknown, OWNER, tx).unwrap_err().code(),
        tonic::Code::NotFound
    );
}

/// A result is the job's only with the job's edge (a preview's at most that), depth
/// bits and eye, framed on the job's object from that eye; a scene and its requests
/// are its uploader's; a worker reads a scene only while it holds a job on it.
#[test]
fn results_must_be_the_jobs_and_scenes_their_owners() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let refused = s.admit(
        &request(hash, 1, Vec3::new(1.0, 0.0, 5.0), Urgency::Now),
        "client-2",
        tx.clone(),
    );
    assert_eq!(refused.unwrap_err().code(), tonic::Code::NotFound);
    assert!(s.scene_of(&hash, "client-2").is_none() && s.scene_of(&hash, OWNER).is_some());
    admit_now(&mut s, hash, 1, 1.0, tx);
    assert!(s.scene_for_worker(&hash, "worker-1").is_none());
    let (wtx, mut wrx) = unbounded_channel();
    let worker = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let job = next_job(&mut wrx).unwrap();
    assert!(s.scene_for_worker(&hash, "worker-1").is_some());
    assert!(s.scene_for_worker(&hash, "worker-2").is_none());
    assert!(s.holds(worker, job.job_id) && !s.holds(worker, job.job_id + 1));
    let eye = Vec3::new(1.0, 0.0, 5.0);
    let bounds = s.object_bounds(&hash, "ball").unwrap();
    let framed =
        |edge: u32| SourceCamera::facing(eye, &bounds, edge, edge, SourceProjection::Orthographic).unwrap();
    let check = |camera: &SourceCamera, bits: DepthBits, eye: Vec3, is_final: bool| {
        s.check_result(job.job_id, camera, bits, eye, is_final)
    };
    assert_eq!(check(&framed(128), DepthBits::Eight, eye, true), Ok(()));
    assert_eq!(check(&framed(4), DepthBits::Eight, eye, false), Ok(()));
    let refusals = [
        check(&framed(4), DepthBits::Eight, eye, true),
        check(&framed(256), DepthBits::Eight, eye, false),
        check(&framed(128), DepthBits::Sixteen, eye, true),
        check(&framed(128), DepthBits::Eight, eye + Vec3::X, true),
        check(
            &SourceCamera {
                origin: framed(128).origin + Vec3::splat(0.01),
                ..framed(128)
            },
            DepthBits::Eight,
            eye,
            true,
        ),
    ];
    for (k, refusal) in refusals.iter().enumerate() {
        assert!(refusal.is_err(), "case {k} accepted");
    }
    s.forged(worker, Status::permission_denied("forged"));
    assert_eq!(
        (s.counters.forged, s.stats().workers, s.stats().queue_now),
        (1, 0, 1)
    );
}

/// One client's requests take at most `max_waiting_per_client` places; another's are
/// still taken in, and a place freed is taken again.
#[test]
fn one_client_cannot_take_every_place() {
    let (mut s, hash) = state_with_scene();
    s.limits.max_waiting_per_client = 2;
    s.add_owner(hash, &"client-2".into());
    let (tx, _rx) = unbounded_channel();
    let ask = |id: u64| request(hash, id, Vec3::new(id as f32, 0.0, 5.0), Urgency::Now);
    s.admit(&ask(1), OWNER, tx.clone()).unwrap();
    s.admit(&ask(2), OWNER, tx.clone()).unwrap();
    let refused = s.admit(&ask(3), OWNER, tx.clone()).unwrap_err();
    assert_eq!(refused.code(), tonic::Code::ResourceExhausted);
    assert!(
        refused.message().contains("--max-waiting-per-client"),
        "{}",
        refused.message()
    );
    let other = Request {
        client_id: "other".into(),
        ..ask(4)
    };
    s.admit(&other, "client-2", tx.clone()).unwrap();
    assert_eq!(s.withdraw("c", &[1]), 1);
    s.admit(&ask(3), OWNER, tx.clone()).unwrap();
    // Ended by a result, a request frees its place too.
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 4, 1, wtx);
    s.dispatch();
    while let Some(job) = next_job(&mut wrx) {
        s.result(job.job_id, pb::ReliefTexture::default(), true, 1);
    }
    assert!(s.waiting_by_owner.is_empty(), "{:?}", s.waiting_by_owner);
}

/// A free slot goes to the client with the fewest jobs running: a second client's
/// request is baked next, ahead of the rest of another's flood.
#[test]
fn a_second_client_is_served_between_anothers_flood() {
    let (mut s, hash) = state_with_scene();
    s.add_owner(hash, &"client-2".into());
    let (tx, _rx) = unbounded_channel();
    for id in 1..=5 {
        admit_now(&mut s, hash, id, id as f32, tx.clone());
    }
    let (wtx, mut wrx) = unbounded_channel();
    let worker = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let first = next_job(&mut wrx).unwrap();
    let other = Request {
        client_id: "other".into(),
        ..request(hash, 9, Vec3::new(9.0, 0.0, 5.0), Urgency::Now)
    };
    s.admit(&other, "client-2", tx.clone()).unwrap();
    s.dispatch();
    assert!(next_job(&mut wrx).is_none(), "the slot is taken");
    // (The other client's needed-now request took the slot back: the worker is told
    // to stop, and finishes first all the same.)
    s.result(first.job_id, pb::ReliefTexture::default(), true, 1);
    s.released(worker, first.job_id);
    s.dispatch();
    assert_eq!(next_job(&mut wrx).unwrap().eye.unwrap().x, 9.0);
}

/// The scene store keeps within its bytes: the least recently used scene no job needs
/// goes first; a scene larger than the store, or one only needed scenes keep out, is
/// refused without evicting anything.
#[test]
fn the_scene_store_evicts_the_least_recently_used_scene_no_job_needs() {
    let (mut s, ball) = state_with_scene();
    s.limits.scene_store_bytes = 100;
    let scene = |bytes: usize| StoredScene {
        encoded: Arc::new(vec![0; bytes]),
        objects: [(
            "ball".to_string(),
            StoredObject {
                bounds: Aabb {
                    min: Vec3::splat(-1.0),
                    max: Vec3::splat(1.0),
                },
                mesh: ContentHash([1; 32]),
            },
        )]
        .into_iter()
        .collect(),
    };
    let owner: Arc<str> = OWNER.into();
    let (a, b, c, d) = (
        ContentHash([1; 32]),
        ContentHash([2; 32]),
        ContentHash([3; 32]),
        ContentHash([4; 32]),
    );
    assert_eq!(s.add_scene(a, scene(40), &owner), Ok(vec![]));
    assert_eq!(s.add_scene(b, scene(40), &owner), Ok(vec![]));
    // `a` is used after `b`: `ball` (stored first, no bytes), then `b`, are the least
    // recently used.
    assert!(s.scene_of(&a, OWNER).is_some());
    assert_eq!(s.add_scene(c, scene(40), &owner), Ok(vec![ball, b]));
    assert_eq!((s.scene_bytes(), s.counters.scenes_evicted), (80, 2));
    assert!(s.scene_of(&b, OWNER).is_none());
    // A job on `a` and one on `c` keep them: nothing can make room.
    let (tx, _rx) = unbounded_channel();
    for (k, hash) in [a, c].into_iter().enumerate() {
        s.admit(
            &request(hash, k as u64 + 1, Vec3::new(0.0, 0.0, 5.0), Urgency::Now),
            OWNER,
            tx.clone(),
        )
        .unwrap();
    }
    assert_eq!(
        s.add_scene(d, scene(40), &owner),
        Err(SceneRefusal::Full { limit: 100 })
    );
    assert_eq!(
        s.add_scene(d, scene(101), &owner),
        Err(SceneRefusal::TooLarge {
            bytes: 101,
            limit: 100
        })
    );
    assert_eq!(s.scene_bytes(), 80);
}

/// A worker that takes a job and shows no progress loses it: the job is stopped there
/// (its slot stays taken, so it gets no more) and goes to another worker; a preview
/// counts as progress.
#[test]
fn a_stalled_job_is_taken_back_and_given_to_another_worker() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 1.0, tx.clone());
    let (hung_tx, mut hung_rx) = unbounded_channel();
    let hung = s.add_worker("hung".into(), "worker-1".into(), 1, 1, hung_tx);
    let progress = s.limits.job_progress;
    let dispatched = Instant::now();
    s.dispatch();
    let job = next_job(&mut hung_rx).unwrap();
    s.expire_stalled_jobs_at(dispatched + progress);
    assert_eq!(s.stats().jobs_stalled, 0);
    // A preview is progress: the clock starts again (a little later than it did).
    std::thread::sleep(Duration::from_millis(2));
    let previewed = Instant::now();
    s.result(job.job_id, pb::ReliefTexture::default(), false, 1);
    s.expire_stalled_jobs_at(previewed + progress);
    assert_eq!(s.stats().jobs_stalled, 0);
    s.expire_stalled_jobs_at(Instant::now() + progress + Duration::from_millis(1));
    assert_eq!((s.stats().jobs_stalled, s.stats().queue_now), (1, 1));
    match hung_rx.try_recv().unwrap().unwrap().kind {
        Some(pb::server_message::Kind::Cancel(c)) => assert_eq!(c.job_id, job.job_id),
        other => panic!("expected a cancel, got {other:?}"),
    }
    let (ok_tx, mut ok_rx) = unbounded_channel();
    s.add_worker("ok".into(), "worker-1".into(), 1, 1, ok_tx);
    s.dispatch();
    assert_eq!(next_job(&mut ok_rx).unwrap().job_id, job.job_id);
    assert!(
        next_job(&mut hung_rx).is_none(),
        "the hung worker got another job"
    );
    assert!(s.holds(hung, job.job_id), "its late answer may still come");
}

/// Every client waiting for a texture, and every later one served from the cache, is
/// sent one texture, not a copy each — the worker's, compacted once to buffers of its
/// own.
#[test]
fn waiters_and_cache_hits_share_one_texture() {
    let (mut s, hash) = state_with_scene();
    let (tx, mut rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 1.0, tx.clone());
    let merged = Request {
        client_id: "other".into(),
        ..request(hash, 2, Vec3::new(1.0, 0.0, 5.0), Urgency::Now)
    };
    s.admit(&merged, OWNER, tx.clone()).unwrap();
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let job = next_job(&mut wrx).unwrap();
    // As decoded from the wire: a slice of the whole message's (larger) buffer.
    let message = tonic::codegen::Bytes::from(vec![7u8; 1 << 20]);
    let texture = pb::ReliefTexture {
        albedo: message.slice(100..100 + 3 * 16 * 16),
        ..Default::default()
    };
    s.result(job.job_id, texture, true, 1);
    let served: Vec<_> = std::iter::from_fn(|| rx.try_recv().ok())
        .map(|r| r.unwrap().texture.unwrap())
        .collect();
    assert_eq!(served.len(), 2);
    let hit = match s.admit(
        &request(hash, 3, Vec3::new(1.0, 0.0, 5.0), Urgency::Now),
        OWNER,
        tx,
    ) {
        Ok(Admission::Cached(texture)) => texture,
        other => panic!("expected a cache hit, got {other:?}"),
    };
    let shared = hit.albedo.as_ptr();
    let within = message.as_ptr_range();
    assert!(
        !within.contains(&shared),
        "the cache keeps the whole message's buffer alive"
    );
    for t in &served {
        assert_eq!(t.albedo.as_ptr(), shared, "a copy was made");
        assert_eq!(t.albedo, hit.albedo);
    }
}

/// With no slot free, a needed-now request of a client with nothing running takes a
/// slot back from the client with the most running (its latest bake, told to stop,
/// queued again first) and is handed that slot at once; a job is taken back once only,
/// and predicted requests take nothing back.
#[test]
fn a_needed_now_request_takes_a_slot_back_once() {
    let (mut s, hash) = state_with_scene();
    for owner in ["client-2", "client-3"] {
        s.add_owner(hash, &owner.into());
    }
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 1.0, tx.clone());
    admit_now(&mut s, hash, 2, 2.0, tx.clone());
    let (wtx, mut wrx) = unbounded_channel();
    let worker = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let running = next_job(&mut wrx).unwrap();
    let from = |owner: &str, id: u64, x: f32, urgency: Urgency| Request {
        client_id: owner.into(),
        ..request(hash, id, Vec3::new(x, 0.0, 5.0), urgency)
    };
    // A predicted request takes nothing back.
    s.admit(
        &from("b", 3, 3.0, Urgency::Predicted { in_ms: 10 }),
        "client-2",
        tx.clone(),
    )
    .unwrap();
    s.dispatch();
    assert!(wrx.try_recv().is_err());
    // A needed-now one does: the running job is told to stop and queued again.
    s.admit(&from("b", 4, 4.0, Urgency::Now), "client-2", tx.clone())
        .unwrap();
    s.dispatch();
    match wrx.try_recv().unwrap().unwrap().kind {
        Some(pb::server_message::Kind::Cancel(c)) => assert_eq!(c.job_id, running.job_id),
        other => panic!("expected a cancel, got {other:?}"),
    }
    assert_eq!(s.stats().jobs_preempted, 1);
    // Its slot goes to the needed-now request at once, before the worker answers the
    // stop (the bake stops within a block of rays); the answer frees nothing more.
    assert_eq!(next_job(&mut wrx).unwrap().eye.unwrap().x, 4.0);
    s.stopped();
    s.released(worker, running.job_id);
    s.dispatch();
    assert!(wrx.try_recv().is_err(), "the slot was lent and taken back twice");
    // Done; the job taken back runs again, and is not taken back a second time.
    let b = s.jobs.keys().copied().find(|&id| s.holds(worker, id)).unwrap();
    s.result(b, pb::ReliefTexture::default(), true, 1);
    s.dispatch();
    assert_eq!(next_job(&mut wrx).unwrap().job_id, running.job_id);
    s.admit(&from("c", 5, 5.0, Urgency::Now), "client-3", tx).unwrap();
    s.dispatch();
    assert!(wrx.try_recv().is_err(), "a job was taken back twice");
    assert_eq!(s.stats().jobs_preempted, 1);
}

/// With no slot free, a small needed-now request of a client with nothing running runs
/// on a worker beside the job filling its slot — nothing taken back, nothing stopped —
/// one such job at a time per worker; a predicted one waits, and so does the next of
/// that client while its first runs. The slot stays the other client's: its next job
/// takes it when its bake ends, not the one beside. (Fails with `EXPRESS_MAX_TEXELS`
/// under 32²: the running job is taken back instead; and with the job beside counted
/// in the slots: the other client's next job takes it back.)
#[test]
fn a_small_request_runs_beside_a_full_worker() {
    let (mut s, hash) = state_with_scene();
    s.add_owner(hash, &"client-2".into());
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 1.0, tx.clone());
    admit_now(&mut s, hash, 5, 5.0, tx.clone());
    let (wtx, mut wrx) = unbounded_channel();
    let worker = s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    s.dispatch();
    let running = next_job(&mut wrx).unwrap();
    let small = |id: u64, urgency: Urgency| Request {
        client_id: "b".into(),
        size: 32,
        ..request(hash, id, Vec3::new(id as f32, 0.0, 5.0), urgency)
    };
    s.admit(
        &small(2, Urgency::Predicted { in_ms: 10 }),
        "client-2",
        tx.clone(),
    )
    .unwrap();
    s.dispatch();
    assert!(wrx.try_recv().is_err(), "a predicted request ran beside");
    s.admit(&small(3, Urgency::Now), "client-2", tx.clone()).unwrap();
    s.admit(&small(4, Urgency::Now), "client-2", tx.clone()).unwrap();
    s.dispatch();
    let beside = next_job(&mut wrx).expect("a job, not a stop");
    assert_eq!(beside.eye.unwrap().x, 3.0);
    assert!(wrx.try_recv().is_err(), "a second job ran beside");
    assert_eq!(s.stats().jobs_preempted, 0);
    assert!(s.holds(worker, running.job_id) && s.holds(worker, beside.job_id));
    // The slot's bake ends: the slot goes to its client's next job.
    s.result(running.job_id, pb::ReliefTexture::default(), true, 1);
    s.dispatch();
    assert_eq!(next_job(&mut wrx).expect("a job, not a stop").eye.unwrap().x, 5.0);
    assert_eq!(s.stats().jobs_preempted, 0);
    // Done, the next of the second client runs beside in turn.
    s.result(beside.job_id, pb::ReliefTexture::default(), true, 1);
    s.dispatch();
    assert_eq!(next_job(&mut wrx).unwrap().eye.unwrap().x, 4.0);
    assert_eq!(s.stats().jobs_preempted, 0);
}

/// A worker that never answers a stop (it heartbeats, but hangs on the job) keeps that
/// slot, but holds preemption off only for `STOP_GRACE`: after it, a needed-now request
/// of another client takes a slot back again (before, one unanswered stop turned
/// preemption off for good).
#[test]
fn a_stop_never_answered_holds_preemption_off_for_a_grace_only() {
    let (mut s, hash) = state_with_scene();
    for owner in ["client-2", "client-3", "client-4"] {
        s.add_owner(hash, &owner.into());
    }
    let (tx, _rx) = unbounded_channel();
    admit_now(&mut s, hash, 1, 1.0, tx.clone());
    admit_now(&mut s, hash, 2, 2.0, tx.clone());
    let (wtx, mut wrx) = unbounded_channel();
    let worker = s.add_worker("w".into(), "worker-1".into(), 2, 1, wtx);
    s.dispatch();
    assert!(next_job(&mut wrx).is_some() && next_job(&mut wrx).is_some());
    let from = |owner: &str, id: u64, x: f32| Request {
        client_id: owner.into(),
        ..request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Now)
    };
    let cancels = |rx: &mut tokio::sync::mpsc::UnboundedReceiver<_>| {
        std::iter::from_fn(|| rx.try_recv().ok())
            .filter(|m: &Result<pb::ServerMessage, Status>| {
                matches!(
                    m,
                    Ok(pb::ServerMessage {
                        kind: Some(pb::server_message::Kind::Cancel(_))
                    })
                )
            })
            .count()
    };
    s.admit(&from("b", 3, 3.0), "client-2", tx.clone()).unwrap();
    s.dispatch();
    assert_eq!(
        cancels(&mut wrx),
        1,
        "the first needed-now request takes a slot back"
    );
    // The worker never answers. While the stop is fresh, its slot is coming free.
    s.admit(&from("c", 4, 4.0), "client-3", tx.clone()).unwrap();
    s.dispatch();
    assert_eq!(
        cancels(&mut wrx),
        0,
        "a slot is coming free: nothing more taken back"
    );
    // Past the grace the worker is hung on it: the next one takes another back.
    let aged = std::time::Instant::now() - jobs::STOP_GRACE - std::time::Duration::from_millis(100);
    for told in s.workers.get_mut(&worker).unwrap().stopping.values_mut() {
        *told = aged;
    }
    s.admit(&from("d", 5, 5.0), "client-4", tx).unwrap();
    s.dispatch();
    assert_eq!(cancels(&mut wrx), 1, "preemption is on again");
    assert_eq!(s.stats().jobs_preempted, 2);
}

/// The wait foreseen for a new job is the jobs ahead shared over the slots, each
/// taking the mean time a job took, then its own (the part behind the others is what
/// clients are told as saturation); a prediction that wait would make more than
/// `SHED_SLACK` late is refused — saying the wait in its metadata — where one needed
/// later, a needed-now one and one joining a job already there are taken.
#[test]
fn predictions_the_workers_cannot_finish_in_time_are_refused() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    // Nothing measured yet: nothing foreseen, everything taken.
    assert_eq!(s.estimated_wait(), None);
    admit_now(&mut s, hash, 1, 0.5, tx.clone());
    s.dispatch();
    let job = next_job(&mut wrx).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(100));
    s.result(job.job_id, pb::ReliefTexture::default(), true, 100);
    let took = s.estimated_wait().unwrap();
    assert!(took >= std::time::Duration::from_millis(100), "{took:?}");
    // With the slot free, a new job waits behind none: its own time is all.
    assert_eq!(s.queue_wait(), Some(std::time::Duration::ZERO));
    assert_eq!(s.stats().queue_wait_ms, 0);
    // Thirty more needed now (one running, 29 queued): a new job waits 31 jobs' time,
    // past the slack.
    for id in 2..32 {
        admit_now(&mut s, hash, id, id as f32, tx.clone());
    }
    s.dispatch();
    let wait = s.estimated_wait().unwrap();
    assert!(
        (wait.as_secs_f64() / took.as_secs_f64() - 31.0).abs() < 1e-6,
        "{wait:?} {took:?}"
    );
    // Thirty of them behind the others: the saturation clients see.
    let behind = s.queue_wait().unwrap();
    assert!(
        (behind.as_secs_f64() / took.as_secs_f64() - 30.0).abs() < 1e-6,
        "{behind:?}"
    );
    assert_eq!(s.stats().queue_wait_ms, behind.as_millis() as u32);
    assert!(wait > admission::SHED_SLACK, "{wait:?}");
    let predicted =
        |id: u64, x: f32, in_ms: u64| request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Predicted { in_ms });
    // A burst (the wait long only just now, its mean over time short): taken.
    (s.mean_wait_s, s.mean_wait_at) = (0.0, Some(Instant::now()));
    assert!(s.admit(&predicted(40, 40.0, 0), OWNER, tx.clone()).is_ok());
    // The wait long for a while (its mean over time as long): refused.
    let wait = s.estimated_wait().unwrap();
    s.mean_wait_s = wait.as_secs_f64();
    let refused = s.admit(&predicted(41, 41.0, 0), OWNER, tx.clone()).unwrap_err();
    assert_eq!(refused.code(), tonic::Code::ResourceExhausted);
    let said = saturated_ms(&refused);
    assert_eq!(said, wait.as_millis() as u64);
    assert_eq!(s.stats().predictions_shed, 1);
    // Needed later than the wait (less the slack): taken.
    let later = wait.as_millis() as u64;
    assert!(s.admit(&predicted(42, 42.0, later), OWNER, tx.clone()).is_ok());
    // Joining a queued job, even needed at once: taken.
    assert!(s.admit(&predicted(43, 5.0, 0), OWNER, tx.clone()).is_ok());
    assert_eq!(s.stats().predictions_shed, 1);
    assert!(s.stats().estimated_wait_ms > 0);
}

/// A job whose worker fetched its scene for it took the scene's load as well as a
/// bake: its time does not count as what the jobs to come will take (at a worker 100
/// ms away over a lossy link, the first jobs' seconds held the foreseen wait long
/// enough to refuse a lone client's predictions at its flight's start).
#[test]
fn a_job_that_loaded_its_scene_is_not_timed() {
    let (mut s, hash) = state_with_scene();
    let (tx, _rx) = unbounded_channel();
    let (wtx, mut wrx) = unbounded_channel();
    s.add_worker("w".into(), "worker-1".into(), 1, 1, wtx);
    admit_now(&mut s, hash, 1, 1.0, tx.clone());
    s.dispatch();
    let first = next_job(&mut wrx).unwrap();
    assert!(s.scene_for_worker(&hash, "worker-1").is_some());
    s.result(first.job_id, pb::ReliefTexture::default(), true, 100);
    assert_eq!(s.estimated_wait(), None, "the scene's load counted as a job");
    admit_now(&mut s, hash, 2, 2.0, tx);
    s.dispatch();
    let second = next_job(&mut wrx).unwrap();
    s.result(second.job_id, pb::ReliefTexture::default(), true, 100);
    assert!(s.estimated_wait().is_some());
}

/// A prediction admitted in time that waits in the queue past its use — a free slot
/// would start it more than `SHED_SLACK` after it was needed — is refused as
/// saturated (saying how late in its metadata) instead of baked, and the slot goes to
/// the next job.
#[test]
fn a_queued_prediction_past_its_use_is_refused_not_baked() {
    let (mut s, hash, mut wrx, running) = one_slot_busy();
    let predicted =
        |id: u64, x: f32, in_ms: u64| request(hash, id, Vec3::new(x, 0.0, 5.0), Urgency::Predicted { in_ms });
    let (soon_tx, mut soon_rx) = unbounded_channel();
    s.admit(&predicted(2, 2.0, 0), OWNER, soon_tx).unwrap();
    let (later_tx, mut later_rx) = unbounded_channel();
    s.admit(&predicted(3, 3.0, 60_000), OWNER, later_tx).unwrap();
    // Both wait behind the running job; nothing is refused while no slot is free.
    s.dispatch();
    assert!(soon_rx.try_recv().is_err());
    // Two seconds on, the slot frees.
    let late = admission::SHED_SLACK + Duration::from_millis(500);
    later_the_slot_frees(&mut s, &running, late);
    let refused = soon_rx.try_recv().unwrap().unwrap_err();
    assert_eq!(refused.code(), tonic::Code::ResourceExhausted, "{refused:?}");
    let said = saturated_ms(&refused);
    assert!(said >= late.as_millis() as u64, "{said} ms late");
    assert_eq!(s.stats().predictions_shed, 1);
    let refused = s.counters.refused.get(&(tonic::Code::ResourceExhausted as i32));
    assert_eq!(refused, Some(&1), "counted among refusals by code");
    // The slot went to the prediction still in time.
    let next = next_job(&mut wrx).unwrap();
    assert_eq!(next.eye.unwrap().x, 3.0);
    assert!(later_rx.try_recv().is_err());
}

/// A queued job serves every request joined to it: one long past its need does not
/// get it refused while another still needs it.
#[test]
fn a_queued_prediction_still_needed_by_a_later_request_is_kept() {
    let (mut s, hash, mut wrx, running) = one_slot_busy();
    let at = Vec3::new(2.0, 0.0, 5.0);
    let (early_tx, mut early_rx) = unbounded_channel();
    s.admit(
        &request(hash, 2, at, Urgency::Predicted { in_ms: 0 }),
        OWNER,
        early_tx,
    )
    .unwrap();
    let (later_tx, mut later_rx) = unbounded_channel();
    s.admit(
        &request(hash, 3, at, Urgency::Predicted { in_ms: 60_000 }),
        OWNER,
        later_tx,
    )
    .unwrap();
    assert_eq!(s.stats().merged, 1, "one job for both");
    later_the_slot_frees(
        &mut s,
        &running,
        admission::SHED_SLACK + Duration::from_millis(500),
    );
    assert_eq!(next_job(&mut wrx).unwrap().eye.unwrap().x, 2.0, "baked");
    assert_eq!(s.stats().predictions_shed, 0);
    assert!(early_rx.try_recv().is_err() && later_rx.try_recv().is_err());
}
