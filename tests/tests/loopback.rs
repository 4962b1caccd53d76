//! The distributed system on 127.0.0.1, real processes and sockets: server, workers,
//! and a client asking for relief textures.

use std::time::{Duration, Instant};

use glam::Vec3;
use tonic::Code;

use relief_client::remote::Remote;
use relief_core::relief::{DepthBits, SourceProjection};
use relief_core::scene::Scene;
use relief_proto::bundle::bundle_for;
use relief_proto::convert::{texture_from_pb, vec3_to_pb};
use relief_proto::pb;
use relief_tests::{
    Running, command, scratch, send_sigterm, spawn_server, start_server, start_server_at, start_worker,
    upload_default, wait_exit, wait_for, worker_command,
};
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

fn request(
    scene: &str,
    object: &str,
    eye: Vec3,
    size: u32,
    id: u64,
    urgency: pb::Urgency,
) -> pb::ImpostorRequest {
    pb::ImpostorRequest {
        scene_hash: scene.to_string(),
        object: object.to_string(),
        eye: Some(vec3_to_pb(eye)),
        size,
        depth_bits: 8,
        urgency: urgency as i32,
        needed_in_ms: 500,
        client_id: "test".into(),
        request_id: id,
        progressive: false,
        // (What the client asks for.)
        projection: pb::SourceProjection::Perspective.into(),
        serve_within: 0.0,
        zstd_planes: false,
        zstd_delta_planes: false,
    }
}

/// Collects a request's stream: previews and the final texture.
async fn collect(
    mut stream: tonic::Streaming<pb::ImpostorResult>,
) -> Result<Vec<pb::ImpostorResult>, tonic::Status> {
    let mut results = Vec::new();
    while let Some(r) = stream.message().await? {
        results.push(r);
    }
    Ok(results)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_texture_over_the_network_equals_a_local_bake() {
    let (_server, url) = start_server(&[]);
    let _workers = [start_worker(&url, &[]), start_worker(&url, &[])];
    let mut remote = Remote::connect(&url, None, "test").await.unwrap();
    let bundle = bundle_for("default").unwrap();
    let hash = remote.put_scene(&bundle).await.unwrap();
    assert_eq!(hash, bundle.hash);
    wait_for(&mut remote, "two workers", |s| s.workers == 2).await;
    let eye = Vec3::new(6.0, 2.5, 4.0);
    let mut req = request(&hash.to_string(), "knot", eye, 128, 1, pb::Urgency::Now);
    req.progressive = true;
    let results = collect(remote.request(req.clone()).await.unwrap()).await.unwrap();
    assert_eq!(results.len(), 2, "a preview, then the final texture");
    assert!(!results[0].r#final && results[1].r#final);
    // (Raw planes for a client that does not read compressed ones.)
    let wire = results[1].texture.as_ref().unwrap();
    assert_eq!(wire.encoding, pb::PlaneEncoding::Raw as i32);
    let got = texture_from_pb("texture", wire).unwrap();
    let scene = Scene::load("default").unwrap();
    let local = bake(
        &ObjectTracer::new(scene.object("knot").unwrap()),
        eye,
        128,
        DepthBits::Eight,
        SourceProjection::Perspective,
    )
    .unwrap();
    assert_eq!(got, local, "the worker's texture differs from a local bake");
    // Asked again: served from the cache — with the planes compressed as the worker
    // sent them, for a client that reads them so.
    req.request_id = 2;
    req.progressive = false;
    req.zstd_planes = true;
    req.zstd_delta_planes = true;
    let again = collect(remote.request(req.clone()).await.unwrap()).await.unwrap();
    assert_eq!(again.len(), 1);
    let wire = again[0].texture.as_ref().unwrap();
    let compressed = [pb::PlaneEncoding::Zstd, pb::PlaneEncoding::ZstdDelta].map(|e| e as i32);
    assert!(compressed.contains(&wire.encoding), "encoding {}", wire.encoding);
    assert!(wire.albedo.len() < results[1].texture.as_ref().unwrap().albedo.len());
    assert_eq!(texture_from_pb("texture", wire).unwrap(), local);
    // A client that reads zstd but not predicted planes never gets those: raw instead.
    req.request_id = 21;
    req.zstd_delta_planes = false;
    let plain_zstd = collect(remote.request(req.clone()).await.unwrap()).await.unwrap();
    let plain_wire = plain_zstd[0].texture.as_ref().unwrap();
    let expected = if wire.encoding == pb::PlaneEncoding::ZstdDelta as i32 {
        pb::PlaneEncoding::Raw
    } else {
        pb::PlaneEncoding::Zstd
    };
    assert_eq!(plain_wire.encoding, expected as i32);
    assert_eq!(texture_from_pb("texture", plain_wire).unwrap(), local);
    req.zstd_delta_planes = true;
    // A client that also takes gRPC's zstd gets the stream plain: its planes are
    // compressed already, and compressing them again would only cost the server.
    let mut zstd_client = pb::impostors_client::ImpostorsClient::new(
        tonic::transport::Endpoint::from_shared(url.clone())
            .unwrap()
            .connect()
            .await
            .unwrap(),
    )
    .accept_compressed(tonic::codec::CompressionEncoding::Zstd);
    req.request_id = 20;
    let response = zstd_client.request(req.clone()).await.unwrap();
    assert_eq!(
        response.metadata().get("grpc-encoding"),
        None,
        "the texture stream is plain"
    );
    let plain = collect(response.into_inner()).await.unwrap();
    assert_eq!(
        texture_from_pb("texture", plain[0].texture.as_ref().unwrap()).unwrap(),
        local
    );
    req.zstd_planes = false;
    // A smaller request at the same eye: the bigger cached texture serves it.
    req.request_id = 3;
    req.size = 64;
    let smaller = collect(remote.request(req.clone()).await.unwrap()).await.unwrap();
    assert_eq!(smaller.len(), 1);
    let served = texture_from_pb("texture", smaller[0].texture.as_ref().unwrap()).unwrap();
    assert_eq!(served, local, "the 64² request gets the cached 128² texture");
    // The same eye in the other projection is another texture, baked for it.
    req.request_id = 4;
    req.projection = pb::SourceProjection::Orthographic.into();
    let parallel = collect(remote.request(req).await.unwrap()).await.unwrap();
    let parallel = texture_from_pb("texture", parallel[0].texture.as_ref().unwrap()).unwrap();
    assert_eq!(
        parallel.camera.centre, None,
        "an orthographic texture has no centre"
    );
    assert_eq!(
        local.camera.centre,
        Some(eye),
        "a perspective texture is seen from its eye"
    );
    // A nearby eye, with a serve_within that takes `eye` in: the cached texture of
    // `eye`; with none, a texture of its own.
    let nearby = eye + Vec3::new(0.05, 0.0, 0.0);
    let mut near = request(&hash.to_string(), "knot", nearby, 128, 5, pb::Urgency::Now);
    near.serve_within = 0.02;
    let shared = collect(remote.request(near.clone()).await.unwrap())
        .await
        .unwrap();
    let shared = texture_from_pb("texture", shared[0].texture.as_ref().unwrap()).unwrap();
    assert_eq!(
        shared, local,
        "a texture made for an eye within serve_within serves"
    );
    near.request_id = 6;
    near.serve_within = 0.0;
    let own = collect(remote.request(near).await.unwrap()).await.unwrap();
    let own = texture_from_pb("texture", own[0].texture.as_ref().unwrap()).unwrap();
    assert_eq!(own.eye, nearby, "with no serve_within, the eye asked for");
    let stats = remote.stats().await.unwrap();
    assert_eq!(
        (stats.requests, stats.cache_hits, stats.served_nearby),
        (8, 5, 1),
        "{stats:?}"
    );
    // Every request's latency is in the histogram, one count per bucket and one over.
    assert_eq!(stats.latency_counts.len(), stats.latency_bucket_ms.len() + 1);
    assert_eq!(stats.latency_counts.iter().sum::<u64>(), 8, "{stats:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_are_refused_with_the_field_named() {
    let (_server, url) = start_server(&[]);
    let (mut remote, hash) = upload_default(&url, None, "test").await;
    let eye = Vec3::new(6.0, 2.5, 4.0);
    let refused = |r: Result<tonic::Streaming<pb::ImpostorResult>, tonic::Status>| r.expect_err("refused");
    let mut nan = request(&hash, "knot", eye, 64, 1, pb::Urgency::Now);
    nan.eye = Some(pb::Vec3 {
        x: f32::NAN,
        y: 0.0,
        z: 0.0,
    });
    let e = refused(remote.request(nan).await);
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("eye.x"), "{}", e.message());
    let e = refused(
        remote
            .request(request(&hash, "teapot", eye, 64, 2, pb::Urgency::Now))
            .await,
    );
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("teapot"), "{}", e.message());
    // (An eye at the knot's centre: eyes are given in the object's own frame.)
    let inside = relief_core::scene::Scene::load("default")
        .unwrap()
        .object("knot")
        .unwrap()
        .local_bounds
        .center();
    let e = refused(
        remote
            .request(request(&hash, "knot", inside, 64, 3, pb::Urgency::Now))
            .await,
    );
    assert_eq!(e.code(), Code::FailedPrecondition);
    let e = refused(
        remote
            .request(request(&"00".repeat(32), "knot", eye, 64, 4, pb::Urgency::Now))
            .await,
    );
    assert_eq!(e.code(), Code::NotFound);
    let e = refused(
        remote
            .request(request(&hash, "knot", eye, 0, 5, pb::Urgency::Now))
            .await,
    );
    assert!(e.message().contains("`size`"), "{}", e.message());
    // A worker registering with no slots.
    let channel = tonic::transport::Endpoint::from_shared(url.clone())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let register = pb::WorkerMessage {
        kind: Some(pb::worker_message::Kind::Register(pb::Register {
            name: "idle".into(),
            slots: 0,
            threads: 1,
        })),
    };
    let e = pb::workers_client::WorkersClient::new(channel)
        .session(tokio_stream::iter([register]))
        .await
        .expect_err("refused");
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("register.slots"), "{}", e.message());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn withdrawn_predictions_are_cancelled() {
    let (_server, url) = start_server(&[]);
    let (mut remote, hash) = upload_default(&url, None, "test").await;
    // No worker yet: three predictions wait in the queue.
    let mut streams = Vec::new();
    for id in 1..=3 {
        let eye = Vec3::new(6.0 + id as f32, 2.5, 4.0);
        streams.push(
            remote
                .request(request(&hash, "knot", eye, 64, id, pb::Urgency::Predicted))
                .await
                .unwrap(),
        );
    }
    wait_for(&mut remote, "three queued", |s| s.queue_predicted == 3).await;
    assert_eq!(remote.withdraw(&[1, 2, 77]).await.unwrap(), 2);
    let stats = wait_for(&mut remote, "one left", |s| s.queue_predicted == 1).await;
    assert_eq!(stats.withdrawn, 2);
    let third = streams.pop().unwrap();
    for s in streams {
        assert_eq!(collect(s).await.unwrap_err().code(), Code::Cancelled);
    }
    // A worker arrives and serves the one still wanted.
    let _worker = start_worker(&url, &[]);
    let results = collect(third).await.unwrap();
    assert!(results.last().unwrap().r#final);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_no_worker_takes_ends_in_an_error() {
    let (_server, url) = start_server(&["--job-timeout-ms", "300"]);
    let (mut remote, hash) = upload_default(&url, None, "test").await;
    let eye = Vec3::new(6.0, 2.5, 4.0);
    let stream = remote
        .request(request(&hash, "knot", eye, 64, 1, pb::Urgency::Now))
        .await
        .unwrap();
    let e = collect(stream).await.unwrap_err();
    assert_eq!(e.code(), Code::DeadlineExceeded, "{e:?}");
    assert!(e.message().contains("no worker took it"), "{}", e.message());
    assert_eq!(remote.stats().await.unwrap().jobs_timed_out, 1);
}

/// Asks for a bake that takes seconds (the 4096² rock, request 1, a 1024² preview
/// first) and waits until its preview has come: the worker is then baking the final.
async fn start_long_bake(remote: &mut Remote, hash: &str) -> tonic::Streaming<pb::ImpostorResult> {
    let eye = Vec3::new(0.5, 2.0, 8.0);
    let mut stream = remote
        .request(pb::ImpostorRequest {
            progressive: true,
            ..request(hash, "rock", eye, 4096, 1, pb::Urgency::Now)
        })
        .await
        .unwrap();
    let preview = stream.message().await.unwrap().unwrap();
    assert!(!preview.r#final);
    stream
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn withdrawn_running_jobs_stop_on_their_worker() {
    let (_server, url) = start_server(&[]);
    let _worker = start_worker(&url, &[]);
    let (mut remote, hash) = upload_default(&url, None, "test").await;
    let stats = wait_for(&mut remote, "a worker", |s| s.workers == 1).await;
    assert!(stats.worker_slots == 1 && stats.worker_threads >= 1, "{stats:?}");
    // A long bake; the client cancels the call while it runs.
    let stream = start_long_bake(&mut remote, &hash).await;
    drop(stream);
    // The server withdraws it and the worker stops mid-bake (says so, sends nothing
    // more): nothing is left running.
    let stats = wait_for(&mut remote, "the worker stopping it", |s| s.jobs_stopped == 1).await;
    assert_eq!(
        (stats.withdrawn, stats.jobs_in_flight, stats.results_discarded),
        (1, 0, 0),
        "{stats:?}"
    );
    // The same for a running job whose request is withdrawn.
    let stream = start_long_bake(&mut remote, &hash).await;
    assert_eq!(remote.withdraw(&[1]).await.unwrap(), 1);
    assert_eq!(collect(stream).await.unwrap_err().code(), Code::Cancelled);
    let stats = wait_for(&mut remote, "the worker stopping it", |s| s.jobs_stopped == 2).await;
    assert_eq!((stats.withdrawn, stats.results_discarded), (2, 0), "{stats:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_killed_workers_job_is_answered_by_another() {
    // (A slow machine's long bakes must not meet the job timeout.)
    let (_server, url) = start_server(&["--lease-ms", "400", "--job-timeout-ms", "600000"]);
    let mut first = start_worker(&url, &[]);
    let (mut remote, hash) = upload_default(&url, None, "test").await;
    wait_for(&mut remote, "a worker", |s| s.workers == 1).await;
    // A big bake of the heavy object, so the worker is killed while holding it.
    let stream = start_long_bake(&mut remote, &hash).await;
    first.0.kill().unwrap();
    let _second = start_worker(&url, &[]);
    let results = collect(stream).await.expect("the request is still answered");
    assert!(results.last().unwrap().r#final);
    let stats = remote.stats().await.unwrap();
    assert!(stats.requeued >= 1, "{stats:?}");
}

/// SIGTERM: the worker takes no new job, finishes (and sends) the one it holds, then
/// exits cleanly.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_told_to_stop_finishes_its_job_first() {
    let (_server, url) = start_server(&["--job-timeout-ms", "600000"]);
    // (On one thread, the held bake lasts seconds: the checks below come well within
    // it.)
    let mut worker = Running(
        worker_command(&url)
            .args(["--slots", "2"])
            .env("RAYON_NUM_THREADS", "1")
            .spawn()
            .expect("starting relief-worker"),
    );
    let (mut remote, hash) = upload_default(&url, None, "test").await;
    wait_for(&mut remote, "a worker", |s| s.workers == 1).await;
    let stream = start_long_bake(&mut remote, &hash).await;
    send_sigterm(&worker.0);
    // Draining, it is handed nothing new, though it has a free slot.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let eye = Vec3::new(6.0, 2.5, 4.0);
    let _waiting = remote
        .request(request(&hash, "knot", eye, 64, 2, pb::Urgency::Now))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let stats = remote.stats().await.unwrap();
    assert_eq!((stats.queue_now, stats.jobs_in_flight), (1, 1), "{stats:?}");
    let results = collect(stream).await.expect("the held job is still answered");
    assert!(results.last().unwrap().r#final);
    let status = tokio::task::block_in_place(|| wait_exit(&mut worker.0, Duration::from_secs(30)));
    assert!(status.success(), "{status}");
    wait_for(&mut remote, "the worker gone", |s| s.workers == 0).await;
}

/// Told to stop (SIGTERM), a server and a worker remove the scene directories they
/// made for themselves in the temp dir as they exit — the server within its grace
/// period although the worker's session is still open, the worker then.
#[test]
fn stopped_processes_remove_their_scene_directories() {
    let temp = scratch("stopping");
    let entries = || std::fs::read_dir(&temp).expect("the scratch temp dir").count();
    let mut server = command("relief-server");
    server
        .args(["--listen", "127.0.0.1:0"])
        .env("TMPDIR", temp.path());
    let (mut server, url) = spawn_server(server);
    let worker = worker_command(&url)
        .env("TMPDIR", temp.path())
        .spawn()
        .expect("starting relief-worker");
    let mut worker = Running(worker);
    let start = Instant::now();
    while entries() < 2 {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no scene directories made"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // (Time to register: its session is the open call the server must not wait for.)
    std::thread::sleep(Duration::from_millis(500));
    send_sigterm(&server.0);
    let status = wait_exit(&mut server.0, Duration::from_secs(10));
    assert!(status.success(), "server: {status}");
    assert_eq!(entries(), 1, "the server's directory is left");
    send_sigterm(&worker.0);
    let status = wait_exit(&mut worker.0, Duration::from_secs(15));
    assert!(status.success(), "worker: {status}");
    assert_eq!(entries(), 0, "the worker's directory is left");
}

/// A worker whose server goes away dials again (with backoff) until one answers at
/// the address again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_reconnects_when_the_server_returns() {
    let (server, url) = start_server(&[]);
    let _worker = start_worker(&url, &[]);
    let mut remote = Remote::connect(&url, None, "test").await.unwrap();
    wait_for(&mut remote, "a worker", |s| s.workers == 1).await;
    drop(server);
    let address = url.strip_prefix("http://").unwrap();
    let (_again, url) = start_server_at(address, &[]);
    let mut remote = Remote::connect(&url, None, "test").await.unwrap();
    wait_for(&mut remote, "the worker back", |s| s.workers == 1).await;
}

/// A worker whose server keeps dropping it redials with doubling delays — 100, 200,
/// 400, 800 ms — measured between its attempts to reach a listener on 127.0.0.1 that
/// accepts each connection and closes it at once. (An attempt may open a second
/// connection at once — the gRPC channel's own reconnect —: connections within 50 ms
/// of the last count as one attempt.)
#[test]
fn a_dropped_worker_redials_with_doubling_delays() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let _worker = start_worker(&url, &[]);
    let start = Instant::now();
    let mut connections = Vec::new();
    while connections.len() < 5 && start.elapsed() < Duration::from_secs(20) {
        match listener.accept() {
            Ok((stream, _)) => {
                let now = Instant::now();
                if connections
                    .last()
                    .is_none_or(|&last| now - last > Duration::from_millis(50))
                {
                    connections.push(now);
                }
                drop(stream);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => panic!("accept: {e}"),
        }
    }
    assert_eq!(connections.len(), 5, "the worker did not redial");
    let gaps: Vec<f64> = connections
        .windows(2)
        .map(|w| (w[1] - w[0]).as_secs_f64() * 1e3)
        .collect();
    // Judged by each attempt's time since the first, 100·(2^k − 1) ms: a connection
    // noticed late (this thread starved by a busy machine) delays only its own time,
    // not the next attempt's. The margins leave room for that, not for a constant
    // delay: c, 2c, 3c, 4c cannot all fall within them.
    let since_first: Vec<f64> = connections
        .iter()
        .map(|&t| (t - connections[0]).as_secs_f64() * 1e3)
        .collect();
    for (k, &at) in since_first.iter().enumerate().skip(1) {
        let expected = 100.0 * f64::from((1u32 << k) - 1);
        assert!(
            (0.9 * expected..expected + 300.0).contains(&at),
            "attempt {k}: {at:.0} ms after the first, not about {expected} ms (gaps: {gaps:.0?})"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_and_authentication() {
    let (_server, url) = start_server(&["--token", "s3cret"]);
    let channel = tonic::transport::Endpoint::from_shared(url.clone())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
    let reply = health
        .check(tonic_health::pb::HealthCheckRequest {
            service: "relief.v1.Impostors".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        reply.status,
        tonic_health::pb::health_check_response::ServingStatus::Serving as i32
    );
    let mut anonymous = Remote::connect(&url, None, "test").await.unwrap();
    assert_eq!(anonymous.stats().await.unwrap_err().code(), Code::Unauthenticated);
    let mut wrong = Remote::connect(&url, Some("guess"), "test").await.unwrap();
    assert_eq!(wrong.stats().await.unwrap_err().code(), Code::Unauthenticated);
    let mut right = Remote::connect(&url, Some("s3cret"), "test").await.unwrap();
    assert!(right.stats().await.is_ok());
    // A worker with the wrong token stops with an error naming it: retrying would not
    // mend it.
    let worker = worker_command(&url)
        .args(["--token", "guess"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // (Killed on drop if it keeps retrying and the wait panics.)
    let mut worker = Running(worker);
    let status = tokio::task::block_in_place(|| wait_exit(&mut worker.0, Duration::from_secs(20)));
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut worker.0.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(
        !status.success() && stderr.contains("--token"),
        "{status}: {stderr}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_with_a_self_signed_certificate() {
    let dir = relief_tests::scratch("tls");
    let issued =
        rcgen::generate_simple_self_signed(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
    let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&cert, issued.cert.pem()).unwrap();
    std::fs::write(&key, issued.signing_key.serialize_pem()).unwrap();
    let (_server, url) = start_server(&[
        "--tls-cert",
        cert.to_str().unwrap(),
        "--tls-key",
        key.to_str().unwrap(),
    ]);
    assert!(url.starts_with("https://"), "{url}");
    // A worker trusting the certificate serves a request over TLS end to end.
    let _worker = start_worker(&url, &["--tls-ca", cert.to_str().unwrap()]);
    let mut remote = Remote::connect_with(&url, None, Some(&cert), "test")
        .await
        .unwrap();
    let hash = remote
        .put_scene(&bundle_for("default").unwrap())
        .await
        .unwrap()
        .to_string();
    wait_for(&mut remote, "the worker over TLS", |s| s.workers == 1).await;
    let results = collect(
        remote
            .request(request(
                &hash,
                "sphere",
                Vec3::new(-3.0, 2.0, 5.0),
                32,
                1,
                pb::Urgency::Now,
            ))
            .await
            .unwrap(),
    )
    .await
    .unwrap();
    assert!(results.last().unwrap().r#final);
    // `relief render` against it, trusting the certificate with --tls-ca.
    let out = dir.join("render");
    let run = relief_tests::relief(&[
        "render",
        "--server",
        &url,
        "--tls-ca",
        cert.to_str().unwrap(),
        "--frames",
        "6",
        "--size",
        "64x36",
        "--reference-every",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    assert!(out.join("summary.json").is_file());
    // Without trusting the certificate the connection is refused.
    let mut untrusting = match Remote::connect(&url, None, "test").await {
        Err(e) => {
            assert!(e.to_string().contains("connecting"), "{e}");
            return;
        }
        Ok(r) => r,
    };
    assert!(untrusting.stats().await.is_err());
}

/// A server whose certificate is marked as a CA is refused by the TLS layer; the error
/// says so and what to do, not only "transport error".
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_certificate_the_tls_layer_refuses_is_named() {
    let dir = relief_tests::scratch("tls-ca-flag");
    let key = rcgen::KeyPair::generate().unwrap();
    let mut params =
        rcgen::CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
    params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    let issued = params.self_signed(&key).unwrap();
    let (cert, key_file) = (dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&cert, issued.pem()).unwrap();
    std::fs::write(&key_file, key.serialize_pem()).unwrap();
    let (_server, url) = start_server(&[
        "--tls-cert",
        cert.to_str().unwrap(),
        "--tls-key",
        key_file.to_str().unwrap(),
    ]);
    let refused = match Remote::connect_with(&url, None, Some(&cert), "test").await {
        Err(e) => e.to_string(),
        Ok(_) => panic!("connected to a server whose certificate is a CA's"),
    };
    eprintln!("{refused}");
    assert!(
        refused.contains("marked as a CA") && refused.contains("leaf certificate"),
        "{refused}"
    );
}
