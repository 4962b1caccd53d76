//! The server among callers it cannot trust: a real `relief-server` on 127.0.0.1 with a
//! credential per client and per worker, and callers that misuse theirs — a worker's
//! credential asking for textures, a client's opening a worker session, a client
//! withdrawing another's request or reading its scene, a worker answering for a job
//! leased to another, or with a texture that is not the job's.

use std::time::{Duration, Instant};

use glam::Vec3;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tonic::Code;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;

use relief_client::remote::Remote;
use relief_core::relief::{DepthBits, SourceProjection};
use relief_core::scene::Scene;
use relief_proto::auth::BearerToken;
use relief_proto::bundle::bundle_for;
use relief_proto::convert::{texture_to_pb, vec3_to_pb};
use relief_proto::pb;
use relief_tests::{
    Running, start_server, start_worker, upload_default, wait_exit, wait_for, worker_command,
};
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

/// The server's credentials: two clients and two workers.
const SERVER_ARGS: [&str; 8] = [
    "--client-token",
    "client-one",
    "--client-token",
    "client-two",
    "--worker-token",
    "worker-one",
    "--worker-token",
    "worker-two",
];

/// An eye outside the default scene's sphere.
const EYE: Vec3 = Vec3::new(6.0, 2.5, 4.0);

fn ask(scene: &str, id: u64, size: u32, client_id: &str) -> pb::ImpostorRequest {
    pb::ImpostorRequest {
        scene_hash: scene.to_string(),
        object: "sphere".into(),
        eye: Some(vec3_to_pb(EYE)),
        size,
        depth_bits: 8,
        urgency: pb::Urgency::Now as i32,
        needed_in_ms: 0,
        client_id: client_id.into(),
        request_id: id,
        progressive: false,
        projection: pb::SourceProjection::Orthographic.into(),
        serve_within: 0.0,
        zstd_planes: false,
        zstd_delta_planes: false,
    }
}

async fn channel(url: &str) -> Channel {
    tonic::transport::Endpoint::from_shared(url.to_string())
        .expect("url")
        .connect()
        .await
        .expect("connect")
}

type Scenes = pb::scenes_client::ScenesClient<InterceptedService<Channel, BearerToken>>;

async fn scenes_client(url: &str, token: &str) -> Scenes {
    let auth = BearerToken::new(Some(token)).expect("token");
    pb::scenes_client::ScenesClient::with_interceptor(channel(url).await, auth)
        .send_compressed(tonic::codec::CompressionEncoding::Zstd)
}

/// Whether the credential may read scene `hash` (its first chunk comes), or the code
/// it is refused with.
async fn read_scene(url: &str, token: &str, hash: &str) -> Result<(), Code> {
    let mut client = scenes_client(url, token).await;
    let mut stream = client
        .get_scene(pb::SceneRef { hash: hash.into() })
        .await
        .map_err(|s| s.code())?
        .into_inner();
    stream
        .message()
        .await
        .map_err(|s| s.code())?
        .map(|_| ())
        .ok_or(Code::Unknown)
}

/// A worker session driven by hand: what it sends, and what the server sends it.
struct FakeWorker {
    out: mpsc::Sender<pb::WorkerMessage>,
    inbound: tonic::Streaming<pb::ServerMessage>,
}

impl FakeWorker {
    async fn register(url: &str, token: &str) -> Result<FakeWorker, tonic::Status> {
        let auth = BearerToken::new(Some(token)).expect("token");
        let mut client = pb::workers_client::WorkersClient::with_interceptor(channel(url).await, auth);
        let (out, rx) = mpsc::channel(16);
        let register = pb::worker_message::Kind::Register(pb::Register {
            name: format!("fake-{token}"),
            slots: 1,
            threads: 1,
        });
        out.send(pb::WorkerMessage { kind: Some(register) })
            .await
            .expect("send");
        let inbound = client.session(ReceiverStream::new(rx)).await?.into_inner();
        Ok(FakeWorker { out, inbound })
    }

    /// The next job the server hands it (bounded wait).
    async fn job(&mut self) -> pb::Job {
        let message = tokio::time::timeout(Duration::from_secs(20), self.inbound.message())
            .await
            .expect("a job within 20 s")
            .expect("the session is open")
            .expect("a message");
        match message.kind {
            Some(pb::server_message::Kind::Job(job)) => job,
            other => panic!("expected a job, got {other:?}"),
        }
    }

    async fn answer(&self, job_id: u64, texture: pb::ReliefTexture) {
        let result = pb::worker_message::Kind::Result(pb::JobResult {
            job_id,
            texture: Some(texture),
            r#final: true,
            bake_ms: 1,
        });
        self.out
            .send(pb::WorkerMessage { kind: Some(result) })
            .await
            .expect("send");
    }

    /// How the server ends the session (bounded wait): the status code.
    async fn ended(&mut self) -> Code {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, self.inbound.message()).await {
                Err(_) => panic!("the session was not ended within 20 s"),
                Ok(Err(status)) => return status.code(),
                Ok(Ok(None)) => return Code::Ok,
                Ok(Ok(Some(_))) => continue,
            }
        }
    }
}

/// A 1×1 texture, well formed, for any job.
fn tiny_texture() -> pb::ReliefTexture {
    let v = |x: f32, y: f32, z: f32| Some(pb::Vec3 { x, y, z });
    pb::ReliefTexture {
        width: 1,
        height: 1,
        origin: v(0.0, 0.0, 0.0),
        a: v(1.0, 0.0, 0.0),
        b: v(0.0, -1.0, 0.0),
        f: v(0.0, 0.0, -1.0),
        depth_near: 0.0,
        depth_far: 1.0,
        depth_bits: 8,
        eye: Some(vec3_to_pb(EYE)),
        albedo: vec![255, 0, 0].into(),
        normal: vec![128, 128, 255].into(),
        depth: vec![0].into(),
        centre: None,
        encoding: pb::PlaneEncoding::Raw.into(),
        hidden_texels: vec![],
        hidden_sides: vec![],
        hidden_inward: vec![],
        hidden_depths: vec![],
    }
}

/// Each credential does its own job only, and a client's requests and scenes are its
/// own.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_credential_may_do_its_own_job_only() {
    let (_server, url) = start_server(&SERVER_ARGS);
    // A worker's credential asks for nothing as a client…
    let mut as_client = Remote::connect(&url, Some("worker-one"), "w")
        .await
        .expect("connect");
    assert_eq!(
        as_client.stats().await.expect_err("refused").code(),
        Code::PermissionDenied
    );
    let bundle = bundle_for("default").expect("default scene");
    assert_eq!(
        as_client.put_scene(&bundle).await.expect_err("refused").code(),
        Code::PermissionDenied
    );
    // … and a client's opens no worker session: the worker process stops, naming it.
    let worker = worker_command(&url)
        .args(["--token", "client-one"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("worker");
    let mut worker = Running(worker);
    let status = tokio::task::block_in_place(|| wait_exit(&mut worker.0, Duration::from_secs(20)));
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut worker.0.stderr.take().expect("stderr"), &mut stderr).expect("read");
    assert!(
        !status.success() && stderr.contains("not a worker"),
        "{status}: {stderr}"
    );

    // Client one's scene and request are its own.
    let mut one = Remote::connect(&url, Some("client-one"), "same-id")
        .await
        .expect("connect");
    let hash = one.put_scene(&bundle).await.expect("upload").to_string();
    let mut two = Remote::connect(&url, Some("client-two"), "same-id")
        .await
        .expect("connect");
    let refused = two
        .request(ask(&hash, 1, 32, "same-id"))
        .await
        .expect_err("not its scene");
    assert_eq!(refused.code(), Code::NotFound, "{refused}");
    assert_eq!(read_scene(&url, "client-two", &hash).await, Err(Code::NotFound));
    assert_eq!(read_scene(&url, "client-one", &hash).await, Ok(()));
    // No worker holds a job on it: no worker credential reads it.
    assert_eq!(read_scene(&url, "worker-one", &hash).await, Err(Code::NotFound));
    // With no worker, client one's request waits; client two, naming the same client
    // id and request id, withdraws nothing.
    let _waiting = one.request(ask(&hash, 7, 32, "same-id")).await.expect("queued");
    wait_for(&mut one, "the request to wait", |s| s.queue_now == 1).await;
    assert_eq!(two.withdraw(&[7]).await.expect("withdraw"), 0);
    assert_eq!(one.stats().await.expect("stats").queue_now, 1);
    assert_eq!(one.withdraw(&[7]).await.expect("withdraw"), 1);
    // A client id is short, and a request message small: both refused, naming why.
    let long = "x".repeat(300);
    let refused = one.request(ask(&hash, 8, 32, &long)).await.expect_err("too long");
    assert!(
        refused.code() == Code::InvalidArgument && refused.message().contains("client_id"),
        "{refused}"
    );
    let huge = "x".repeat(1 << 20);
    let refused = one.request(ask(&hash, 9, 32, &huge)).await.expect_err("too big");
    assert_ne!(refused.code(), Code::Ok, "{refused}");
    assert!(one.stats().await.is_ok(), "the server still serves");
    // A second upload of the same content makes client two an owner too: it sent it all.
    two.put_scene(&bundle).await.expect("upload");
    assert_eq!(read_scene(&url, "client-two", &hash).await, Ok(()));
}

/// A worker answers only for the jobs leased to it, and only with the texture asked
/// for: a forged answer drops the worker, its job goes to another, and the client gets
/// the real texture.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_answers_only_for_its_own_jobs_with_the_texture_asked_for() {
    let (_server, url) = start_server(&SERVER_ARGS);
    let (mut client, hash) = upload_default(&url, Some("client-one"), "c").await;
    let mut leased = FakeWorker::register(&url, "worker-one").await.expect("session");
    wait_for(&mut client, "the fake worker", |s| s.workers == 1).await;
    let mut results = client.request(ask(&hash, 1, 64, "c")).await.expect("queued");
    let job = leased.job().await;
    assert_eq!(job.size, 64);
    // The worker that holds the job may read its scene.
    assert_eq!(read_scene(&url, "worker-one", &job.scene_hash).await, Ok(()));

    // Another worker answers for a job it was never given — with the very texture the
    // job asks for: dropped all the same.
    let mut forger = FakeWorker::register(&url, "worker-two").await.expect("session");
    wait_for(&mut client, "the second fake worker", |s| s.workers == 2).await;
    assert_eq!(
        read_scene(&url, "worker-two", &job.scene_hash).await,
        Err(Code::NotFound)
    );
    let scene = Scene::load("default").expect("default scene");
    let sphere = ObjectTracer::new(scene.object("sphere").expect("sphere"));
    let genuine = bake(&sphere, EYE, 64, DepthBits::Eight, SourceProjection::Orthographic).expect("bake");
    forger.answer(job.job_id, texture_to_pb(&genuine)).await;
    assert_eq!(forger.ended().await, Code::PermissionDenied);
    let after = wait_for(&mut client, "the forger dropped", |s| s.workers == 1).await;
    assert_eq!(after.workers_dropped_forged, 1);

    // The worker holding the job answers with a 1×1 texture for a 64² job: dropped too,
    // and the job goes back to the queue.
    leased.answer(job.job_id, tiny_texture()).await;
    assert_eq!(leased.ended().await, Code::PermissionDenied);
    let after = wait_for(&mut client, "the leased worker dropped", |s| s.workers == 0).await;
    assert_eq!((after.workers_dropped_forged, after.queue_now), (2, 1));

    // A real worker makes the texture, and the client gets it, whole.
    let _worker = start_worker(&url, &["--token", "worker-one"]);
    let result = tokio::time::timeout(Duration::from_secs(60), results.message())
        .await
        .expect("a result within 60 s")
        .expect("no error")
        .expect("a result");
    let texture = result.texture.expect("texture");
    assert!(result.r#final);
    assert_eq!((texture.width, texture.height), (64, 64));
}

/// One client's flood does not starve another's: with one worker busy on a flood of
/// another client's requests, a second client's small requests, one after another, run
/// beside the flood's bake (taking no slot back: fails with `EXPRESS_MAX_TEXELS` under
/// their 32²), before the rest of the flood and about as fast as on an idle server
/// (their median latencies, and the ratio, printed — one latency each varied 3-fold
/// from run to run at a millisecond; fails with the small bakes on the thread pool).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_from_one_client_does_not_starve_another() {
    let (_server, url) = start_server(&SERVER_ARGS);
    let _worker = start_worker(&url, &["--token", "worker-one"]);
    let bundle = bundle_for("default").expect("scene");
    let mut flood = Remote::connect(&url, Some("client-one"), "flood")
        .await
        .expect("connect");
    let hash = flood.put_scene(&bundle).await.expect("upload").to_string();
    let mut single = Remote::connect(&url, Some("client-two"), "single")
        .await
        .expect("connect");
    single.put_scene(&bundle).await.expect("upload");
    wait_for(&mut single, "the worker", |s| s.workers == 1).await;
    let at = |k: u64| pb::ImpostorRequest {
        eye: Some(vec3_to_pb(EYE + Vec3::new(0.0, 0.01 * k as f32, 0.0))),
        ..ask(&hash, k, 32, "single")
    };
    let timed = |mut stream: tonic::Streaming<pb::ImpostorResult>| async move {
        let start = Instant::now();
        let result = tokio::time::timeout(Duration::from_secs(60), stream.message())
            .await
            .expect("a result within 60 s")
            .expect("no error")
            .expect("a result");
        assert!(result.r#final);
        start.elapsed()
    };
    // (The first request loads the scene on the worker.)
    timed(single.request(at(0)).await.expect("queued")).await;
    const REPEATS: u64 = 7;
    let mut idle = Vec::new();
    for k in 1..=REPEATS {
        idle.push(timed(single.request(at(k)).await.expect("queued")).await);
    }
    const FLOOD: u64 = 20;
    let mut flooding = Vec::new();
    for k in 0..FLOOD {
        let request = pb::ImpostorRequest {
            eye: Some(vec3_to_pb(EYE + Vec3::new(0.0, 0.0, 0.01 * k as f32))),
            ..ask(&hash, 100 + k, 1024, "flood")
        };
        flooding.push(flood.request(request).await.expect("queued"));
    }
    wait_for(&mut single, "the flood queued", |s| {
        s.queue_now as u64 >= FLOOD - 2
    })
    .await;
    let mut during = Vec::new();
    for k in 1..=REPEATS {
        during.push(timed(single.request(at(REPEATS + k)).await.expect("queued")).await);
    }
    let stats = single.stats().await.expect("stats");
    let left = stats.queue_now;
    idle.sort();
    during.sort();
    let (idle, during) = (idle[idle.len() / 2], during[during.len() / 2]);
    eprintln!(
        "the single request, median of {REPEATS}: {idle:?} idle, {during:?} during a flood of {FLOOD} 1024² requests ({left} still queued after them), {:.2}x",
        during.as_secs_f64() / idle.as_secs_f64()
    );
    assert!(
        left as u64 >= FLOOD / 2,
        "the single requests waited for the flood: {left} left"
    );
    assert_eq!(
        stats.jobs_preempted, 0,
        "small requests ran beside the flood's bake, taking none back"
    );
    // (The target is 2x; measured 0.8-1.9x over 14 runs, once 4.1x against an idle
    // median of 0.45 ms: a few milliseconds' slack for a busy machine. With the small
    // bakes spread over the worker's thread pool, behind the big bake holding it:
    // 8-28 ms, 8-29x.)
    assert!(
        during < idle * 2 + Duration::from_millis(5),
        "{during:?} during the flood against {idle:?} idle"
    );
}

/// A server's peak resident memory (`VmHWM`), MiB.
fn peak_rss_mib(pid: u32) -> f64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("/proc status");
    let kib: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM");
    kib / 1024.0
}

/// A scene file of a hundred bytes that names ten million triangles is refused before
/// anything is built: the server's memory does not move.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scene_too_costly_is_refused_before_it_is_built() {
    let (server, url) = start_server(&SERVER_ARGS);
    let dir = relief_tests::scratch("costly-scene");
    let path = dir.join("tree.toml");
    let text =
        "[[objects]]\nname = \"t\"\ngenerator = { kind = \"tree\", seed = 1, depth = 9, leaves = 256 }\n";
    std::fs::write(&path, text).expect("scene file");
    let bundle = relief_proto::bundle::bundle_for(path.to_str().expect("utf-8")).expect("bundle");
    let mut client = Remote::connect(&url, Some("client-one"), "c")
        .await
        .expect("connect");
    let before = peak_rss_mib(server.0.id());
    let start = Instant::now();
    let refused = client.put_scene(&bundle).await.expect_err("too costly");
    let took = start.elapsed();
    let after = peak_rss_mib(server.0.id());
    eprintln!(
        "refused in {took:?}; server peak RSS {before:.0} → {after:.0} MiB: {}",
        refused.message()
    );
    assert!(
        refused.code() == Code::InvalidArgument && refused.message().contains("too large"),
        "{refused}"
    );
    assert!(
        refused.message().contains("scene tree.toml:") && !refused.message().contains("relief-server-"),
        "the error shows the server's own paths: {refused}"
    );
    assert!(
        after < before + 64.0,
        "the server's peak memory grew from {before:.0} to {after:.0} MiB"
    );
    assert!(client.stats().await.is_ok(), "the server still serves");
}

/// A few compressed kilobytes that decompress to 200 MiB are refused at the server's
/// upload bound, with its memory bounded by it; a scene that fails to load leaves no
/// files; scenes past the store's bytes are evicted, least recently used first, files
/// and all.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_and_stored_scenes_are_bounded() {
    let dir = relief_tests::scratch("bounded-uploads");
    let scenes = dir.join("scenes");
    let mut args: Vec<&str> = SERVER_ARGS.to_vec();
    args.extend(["--max-upload-mb", "16", "--scene-store-mb", "3", "--scene-dir"]);
    args.push(scenes.to_str().expect("utf-8"));
    let (server, url) = start_server(&args);
    let before = peak_rss_mib(server.0.id());

    // The bomb: 200 chunks of a MiB of zeros, zstd-compressed on the wire.
    let mut raw = scenes_client(&url, "client-one").await;
    let zeros = vec![0u8; 1 << 20];
    let chunks: Vec<pb::SceneChunk> = (0..200).map(|_| pb::SceneChunk { data: zeros.clone() }).collect();
    let refused = raw
        .put_scene(tokio_stream::iter(chunks))
        .await
        .expect_err("too big");
    let after = peak_rss_mib(server.0.id());
    eprintln!("bomb refused: {refused}; server peak RSS {before:.0} → {after:.0} MiB");
    assert!(
        refused.code() == Code::ResourceExhausted && refused.message().contains("--max-upload-mb"),
        "{refused}"
    );
    assert!(
        after < before + 3.0 * 16.0 + 32.0,
        "peak RSS {before:.0} → {after:.0} MiB"
    );

    // A scene that does not load leaves nothing behind.
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[[objects]]\nname = \"a\"\ngenerator = { kind = \"sphere\", subdivisions = 99 }\n",
    )
    .expect("scene file");
    let mut client = Remote::connect(&url, Some("client-one"), "c")
        .await
        .expect("connect");
    let bundle = relief_proto::bundle::bundle_for(bad.to_str().expect("utf-8")).expect("bundle");
    assert_eq!(
        client.put_scene(&bundle).await.expect_err("does not load").code(),
        Code::InvalidArgument
    );
    let unpacked = || std::fs::read_dir(&scenes).expect("scene dir").count();
    assert_eq!(unpacked(), 0, "a failed load left files");

    // 2.4 MB, then 0.9 MB more in three scenes: past 3 MiB, the first goes, files too.
    let models = relief_tests::shared_models();
    let mut hashes = Vec::new();
    for model in ["stanford-bunny.obj", "fandisk.obj", "spot.obj", "teapot.obj"] {
        let bundle =
            relief_proto::bundle::bundle_for(models.join(model).to_str().expect("utf-8")).expect("bundle");
        hashes.push(client.put_scene(&bundle).await.expect("upload").to_string());
    }
    let stats = client.stats().await.expect("stats");
    assert_eq!(stats.scenes_evicted, 1, "{stats:?}");
    assert!(stats.scene_bytes <= 3 << 20, "{stats:?}");
    assert_eq!(
        read_scene(&url, "client-one", &hashes[0]).await,
        Err(Code::NotFound)
    );
    assert_eq!(read_scene(&url, "client-one", &hashes[3]).await, Ok(()));
    // (Removed off the request's thread: give it a moment.)
    let start = Instant::now();
    while unpacked() != 3 && start.elapsed() < Duration::from_secs(10) {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(unpacked(), 3, "the evicted scene's files are left");
}

/// A worker that takes a job and never answers (while keeping its session alive) loses
/// it to another within the server's progress limit, and is told to stop it; the
/// client gets its texture.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_that_never_answers_loses_its_job_to_another() {
    let mut args: Vec<&str> = SERVER_ARGS.to_vec();
    args.extend(["--job-progress-ms", "500"]);
    let (_server, url) = start_server(&args);
    let (mut client, hash) = upload_default(&url, Some("client-one"), "c").await;
    let mut hung = FakeWorker::register(&url, "worker-one").await.expect("session");
    wait_for(&mut client, "the hung worker", |s| s.workers == 1).await;
    let mut results = client.request(ask(&hash, 1, 64, "c")).await.expect("queued");
    let job = hung.job().await;
    // It heartbeats (keeps its lease) but never answers; a real worker joins.
    let beating = hung.out.clone();
    let heartbeats = tokio::spawn(async move {
        let beat = || pb::WorkerMessage {
            kind: Some(pb::worker_message::Kind::Heartbeat(pb::Heartbeat {})),
        };
        while beating.send(beat()).await.is_ok() {
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    let _worker = start_worker(&url, &["--token", "worker-two"]);
    let start = Instant::now();
    let result = tokio::time::timeout(Duration::from_secs(30), results.message())
        .await
        .expect("a result within 30 s")
        .expect("no error")
        .expect("a result");
    eprintln!("served {:?} after the hung worker took the job", start.elapsed());
    assert!(result.r#final);
    let cancel = tokio::time::timeout(Duration::from_secs(5), hung.inbound.message())
        .await
        .expect("a message within 5 s")
        .expect("the session is open")
        .expect("a message");
    match cancel.kind {
        Some(pb::server_message::Kind::Cancel(c)) => assert_eq!(c.job_id, job.job_id),
        other => panic!("expected the hung worker to be told to stop, got {other:?}"),
    }
    // (The fresh worker's first job waits for the scene to load, which may pass the
    // short limit set here too: at least the hung worker's counts.)
    let stats = client.stats().await.expect("stats");
    assert!(stats.jobs_stalled >= 1 && stats.workers == 2, "{stats:?}");
    heartbeats.abort();
}

/// Idle TCP connections that never speak cannot lock other clients out: with the
/// server limited to 128 file descriptors, 300 of them are held to the server's
/// `--max-connections` and closed after `--first-bytes-ms`, and a client's call still
/// succeeds. (Before, the server ran out of descriptors, its accept loop spun, and
/// every other call timed out.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_connections_cannot_lock_clients_out() {
    let mut server = std::process::Command::new("bash");
    let binary = relief_tests::bin_dir().join("relief-server");
    server.args([
        "-c",
        "ulimit -n 128 && exec \"$0\" --listen 127.0.0.1:0 --max-connections 64 --first-bytes-ms 500",
        binary.to_str().expect("utf-8"),
    ]);
    let (server, url) = relief_tests::spawn_server(server);
    let address = url.trim_start_matches("http://").to_string();
    let idle: Vec<std::net::TcpStream> = tokio::task::block_in_place(|| {
        (0..300)
            .filter_map(|_| {
                std::net::TcpStream::connect_timeout(
                    &address.parse().expect("address"),
                    Duration::from_secs(2),
                )
                .ok()
            })
            .collect()
    });
    tokio::time::sleep(Duration::from_millis(200)).await;
    let start = Instant::now();
    let answered = tokio::time::timeout(Duration::from_secs(20), async {
        let mut client = Remote::connect(&url, None, "c").await.expect("connect");
        client.stats().await
    })
    .await;
    let fds = std::fs::read_dir(format!("/proc/{}/fd", server.0.id()))
        .map(|d| d.count())
        .unwrap_or(0);
    eprintln!(
        "{} idle connections open; a client's call answered after {:?}; server holds {fds} descriptors",
        idle.len(),
        start.elapsed()
    );
    assert!(
        matches!(answered, Ok(Ok(_))),
        "the client's call failed: {answered:?}"
    );
    drop(idle);
}

/// A connection that spoke and then fell silent — it answers the server's keepalive
/// pings, so keepalive never closes it — is closed once it has had no call open for
/// `--idle-connection-ms`, freeing its place among `--max-connections` for a client
/// waiting in the backlog; a connection with a call open all along (a worker's
/// session) stays. (Without the idle limit the waiting client's call timed out.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_connection_idle_past_its_limit_gives_its_place_up() {
    let mut args: Vec<&str> = SERVER_ARGS.to_vec();
    args.extend(["--max-connections", "2", "--idle-connection-ms", "1500"]);
    let (_server, url) = start_server(&args);
    let _worker = start_worker(&url, &["--token", "worker-one"]);
    let mut first = Remote::connect(&url, Some("client-one"), "first")
        .await
        .expect("connect");
    let deadline = Instant::now() + Duration::from_secs(10);
    while first.stats().await.expect("stats").workers != 1 {
        assert!(Instant::now() < deadline, "the worker never registered");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // Both places taken: the worker's session and `first`, now idle.
    let start = Instant::now();
    let waited = tokio::time::timeout(Duration::from_secs(8), async {
        let mut second = Remote::connect(&url, Some("client-two"), "second").await?;
        second.stats().await?;
        Ok::<_, Box<dyn std::error::Error + Send + Sync>>(second)
    })
    .await;
    let waited_for = start.elapsed();
    let mut second = match waited {
        Ok(Ok(second)) => second,
        Ok(Err(e)) => panic!("the waiting client's call failed: {e}"),
        Err(_) => panic!("the waiting client got no place in 8 s"),
    };
    eprintln!("a place came free after {waited_for:?}");
    assert!(
        waited_for >= Duration::from_millis(800),
        "{waited_for:?}: a place was free at once"
    );
    // The worker's session, a call open throughout, was never closed.
    for _ in 0..20 {
        assert_eq!(
            second.stats().await.expect("stats").workers,
            1,
            "the worker's session was closed"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    drop(first);
}

/// A client that asks for a large texture and does not read it loses its connection,
/// not the server its memory: once the answer has waited `--stalled-answer-ms` for the
/// reader to take its next part (HTTP/2 flow control holding the rest), the server
/// closes the connection, and what was left is freed. A client that reads gets the same
/// texture. (Without the limit the stalled answer waited, whole, for as long as the
/// client kept its connection — then was read in full.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_answer_nobody_reads_costs_its_reader_the_connection() {
    let mut args: Vec<&str> = SERVER_ARGS.to_vec();
    args.extend(["--stalled-answer-ms", "1000"]);
    let (_server, url) = start_server(&args);
    let _worker = start_worker(&url, &["--token", "worker-one"]);
    let (mut reader, hash) = relief_tests::upload_default(&url, Some("client-one"), "reader").await;
    // The rock at 2048² with 16-bit depth: noise that compresses little, megabytes
    // past a stream's window.
    let big = |id: u64| pb::ImpostorRequest {
        depth_bits: 16,
        object: "rock".into(),
        eye: Some(vec3_to_pb(Vec3::new(0.5, 2.0, 8.0))),
        ..ask(&hash, id, 2048, "reader")
    };
    let mut read = reader.request(big(1)).await.expect("asked");
    let texture = read.message().await.expect("read").expect("a texture");
    let bytes = texture
        .texture
        .as_ref()
        .map_or(0, |t| t.albedo.len() + t.normal.len() + t.depth.len());
    assert!(bytes > 4 << 20, "{bytes} bytes: not past the window");
    // Asked again on a connection of its own (served from the cache), and not read.
    let (mut idle, _) = relief_tests::upload_default(&url, Some("client-one"), "idle").await;
    let mut unread = idle.request(big(2)).await.expect("asked");
    tokio::time::sleep(Duration::from_millis(3500)).await;
    let late = unread.message().await;
    assert!(
        late.is_err(),
        "the unread answer was kept for 3.5 s: {:?}",
        late.map(|m| m.is_some())
    );
    // The reader's connection is untouched.
    reader.stats().await.expect("the reader's connection is open");
}

/// A soak (not run by CI: `cargo test --release -p relief-tests --test hostile soak --
/// --ignored --nocapture`, `RELIEF_SOAK_S` seconds, 60 by default): two honest clients
/// keep asking for textures from two real workers while a hostile client floods
/// requests it drops, withdraws others' ids, uploads decompression bombs, a forging
/// worker answers every job it gets with a wrong texture (and registers again when
/// dropped), and idle connections come and go. Every honest request must be answered;
/// the counts and the server's peak memory are printed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore]
async fn soak_with_honest_and_hostile_callers() {
    let seconds: u64 = std::env::var("RELIEF_SOAK_S")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(60);
    let mut args: Vec<&str> = SERVER_ARGS.to_vec();
    args.extend([
        "--client-token",
        "client-evil",
        "--max-upload-mb",
        "16",
        "--job-progress-ms",
        "5000",
    ]);
    args.extend(["--max-connections", "128", "--first-bytes-ms", "500"]);
    let (server, url) = start_server(&args);
    let _workers = [
        start_worker(&url, &["--token", "worker-one"]),
        start_worker(&url, &["--token", "worker-one"]),
    ];
    let bundle = bundle_for("default").expect("scene");
    let mut setup = Remote::connect(&url, Some("client-one"), "setup")
        .await
        .expect("connect");
    let hash = setup.put_scene(&bundle).await.expect("upload").to_string();
    wait_for(&mut setup, "the workers", |s| s.workers >= 2).await;
    let until = Instant::now() + Duration::from_secs(seconds);

    let honest = |token: &'static str, id: &'static str| {
        let (url, hash, bundle) = (url.clone(), hash.clone(), bundle.clone());
        tokio::spawn(async move {
            let mut remote = Remote::connect(&url, Some(token), id).await.expect("connect");
            remote.put_scene(&bundle).await.expect("upload");
            let (mut answered, mut failed, mut k) = (0u64, Vec::new(), 0u64);
            while Instant::now() < until {
                k += 1;
                let request = pb::ImpostorRequest {
                    eye: Some(vec3_to_pb(
                        EYE + Vec3::new(0.0005 * (k % 20_000) as f32, 0.0, 0.0),
                    )),
                    ..ask(&hash, k, 64, id)
                };
                // (Read to the stream's end, as the client's source does: a stream dropped
                // after its final result is reset, and h2 ends a connection after a
                // thousand such resets.)
                let outcome = async {
                    let mut stream = remote.request(request).await?;
                    let mut width = None;
                    while let Some(result) = stream.message().await? {
                        if result.r#final {
                            width = result.texture.map(|t| t.width);
                        }
                    }
                    Ok::<_, tonic::Status>(width)
                }
                .await;
                match outcome {
                    Ok(Some(64)) => answered += 1,
                    other => failed.push(format!("{other:?}")),
                }
            }
            (answered, failed)
        })
    };
    let honest_tasks = [honest("client-one", "honest-a"), honest("client-two", "honest-b")];

    // The hostile client: floods it drops, withdrawals of others' ids, bombs.
    let evil = {
        let (url, hash) = (url.clone(), hash.clone());
        tokio::spawn(async move {
            let mut remote = Remote::connect(&url, Some("client-evil"), "honest-a")
                .await
                .expect("connect");
            let _ = remote.put_scene(&bundle_for("default").expect("scene")).await;
            let mut bombs = scenes_client(&url, "client-evil").await;
            let (mut sent, mut k) = (0u64, 0u64);
            while Instant::now() < until {
                for _ in 0..20 {
                    k += 1;
                    let request = pb::ImpostorRequest {
                        eye: Some(vec3_to_pb(EYE + Vec3::new(0.0, 0.002 * (k % 499) as f32, 0.0))),
                        ..ask(&hash, k, 512, "honest-a")
                    };
                    drop(remote.request(request).await);
                    sent += 1;
                }
                let _ = remote.withdraw(&(0..200).collect::<Vec<u64>>()).await;
                let zeros: Vec<pb::SceneChunk> = (0..32)
                    .map(|_| pb::SceneChunk {
                        data: vec![0u8; 1 << 20],
                    })
                    .collect();
                let _ = bombs.put_scene(tokio_stream::iter(zeros)).await;
                let address = url.trim_start_matches("http://").to_string();
                let idle: Vec<_> = (0..50)
                    .filter_map(|_| std::net::TcpStream::connect(&address).ok())
                    .collect();
                tokio::time::sleep(Duration::from_millis(200)).await;
                drop(idle);
            }
            sent
        })
    };
    // The forging worker.
    let forger = {
        let url = url.clone();
        tokio::spawn(async move {
            let mut dropped = 0u64;
            while Instant::now() < until {
                let Ok(mut fake) = FakeWorker::register(&url, "worker-two").await else {
                    continue;
                };
                let next = tokio::time::timeout(Duration::from_secs(2), fake.inbound.message()).await;
                if let Ok(Ok(Some(pb::ServerMessage {
                    kind: Some(pb::server_message::Kind::Job(job)),
                }))) = next
                {
                    fake.answer(job.job_id, tiny_texture()).await;
                    if fake.ended().await == Code::PermissionDenied {
                        dropped += 1;
                    }
                }
            }
            dropped
        })
    };
    let mut answered = 0;
    for task in honest_tasks {
        let (ok, failed) = task.await.expect("honest client");
        assert!(
            failed.is_empty(),
            "{} honest requests failed, e.g. {:?}",
            failed.len(),
            &failed[..failed.len().min(3)]
        );
        answered += ok;
    }
    let flooded = evil.await.expect("hostile client");
    let forgeries = forger.await.expect("forging worker");
    let stats = setup.stats().await.expect("stats");
    eprintln!(
        "{seconds} s: {answered} honest requests answered, none lost; hostile: {flooded} flood requests dropped, \
         {forgeries} forging workers dropped (server counts {}), {} stalled, {} taken back; server peak RSS {:.0} MiB",
        stats.workers_dropped_forged,
        stats.jobs_stalled,
        stats.jobs_preempted,
        peak_rss_mib(server.0.id())
    );
}
