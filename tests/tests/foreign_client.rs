//! gRPC clients that are not ours: Python stubs generated from `proto/` by
//! grpc_tools' protoc ask a real server for a relief texture, Python's stock
//! reflection client lists its services, and the Prometheus project's parser reads the
//! server's and a worker's metrics.
//!
//! The Python packages come from `tests/foreign/requirements.txt`
//! ([`foreign_python`]).

use std::path::Path;
use std::process::Command;

use relief_tests::{foreign_python, scratch, start_server, start_worker};

#[test]
fn a_python_client_generated_from_the_proto_gets_a_texture() {
    let python = foreign_python();
    let (_server, url) = start_server(&[]);
    let _worker = start_worker(&url, &[]);
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (_, hash) = runtime.block_on(relief_tests::upload_default(&url, None, "setup"));
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let stubs = scratch("python-stubs");
    let out = Command::new(&python)
        .arg(root.join("foreign/client.py"))
        .arg(root.join("../proto"))
        .arg(stubs.path())
        .arg(&url)
        .arg(&hash)
        .output()
        .expect("running the Python client");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reply: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    assert_eq!(reply["width"], 64);
    assert_eq!(reply["height"], 64);
    assert_eq!(reply["albedo_bytes"], 64 * 64 * 3);
    assert_eq!(reply["depth_bytes"], 64 * 64);
    let covered = reply["covered"].as_u64().unwrap();
    assert!(covered > 64 * 64 / 4 && covered < 64 * 64, "{reply}");
}

/// Python's `grpcio-reflection`, which asks `grpc.reflection.v1alpha` only, lists the
/// server's services (a server serving reflection `v1` alone answered it UNIMPLEMENTED).
#[test]
fn python_reflection_lists_the_services() {
    let python = foreign_python();
    let (_server, url) = start_server(&[]);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(&python)
        .arg(root.join("foreign/reflection.py"))
        .arg(url.strip_prefix("http://").unwrap())
        .output()
        .expect("running the Python reflection client");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for service in [
        "relief.v1.Impostors",
        "relief.v1.Scenes",
        "relief.v1.Workers",
        "grpc.health.v1.Health",
    ] {
        assert!(stdout.lines().any(|l| l == service), "{service} not in {stdout}");
    }
}

/// A port on 127.0.0.1 free a moment ago (for an address a process must be given).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// The metrics at `url` as the Prometheus project's Python parser reads them: family
/// name → its type and samples `[name, labels, value]`.
fn scrape(python: &Path, url: &str) -> serde_json::Value {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(python)
        .arg(root.join("foreign/metrics.py"))
        .arg(url)
        .output()
        .expect("running the metrics parser");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.trim()).expect("one JSON object")
}

/// The value of the sample `name` with `labels` (all of them given) in `families`.
fn sample(families: &serde_json::Value, name: &str, labels: &[(&str, &str)]) -> f64 {
    let samples = families
        .as_object()
        .unwrap()
        .values()
        .flat_map(|f| f["samples"].as_array().unwrap());
    samples
        .filter(|s| s[0] == name && labels.iter().all(|(k, v)| s[1][k] == *v))
        .map(|s| s[2].as_f64().unwrap())
        .next()
        .unwrap_or_else(|| panic!("no sample {name} {labels:?} in {families}"))
}

/// After a texture is served and a request refused, every series of the server's and
/// the worker's endpoints is there, typed, and says so: the Prometheus parser reads
/// both (OpenMetrics text).
#[test]
fn the_prometheus_parser_reads_the_server_and_worker_metrics() {
    let python = foreign_python();
    let (server_port, worker_port) = (free_port(), free_port());
    let server_metrics = format!("127.0.0.1:{server_port}");
    let (_server, url) = start_server(&["--metrics-listen", &server_metrics]);
    let worker_metrics = format!("127.0.0.1:{worker_port}");
    let _worker = start_worker(&url, &["--metrics-listen", &worker_metrics]);
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let (mut remote, hash) = relief_tests::upload_default(&url, None, "metrics").await;
        relief_tests::wait_for(&mut remote, "a worker", |s| s.workers == 1).await;
        let eye = relief_proto::pb::Vec3 {
            x: 0.0,
            y: 2.0,
            z: 12.0,
        };
        let request = |object: &str, id| relief_proto::pb::ImpostorRequest {
            scene_hash: hash.clone(),
            object: object.into(),
            eye: Some(eye),
            size: 64,
            depth_bits: 8,
            urgency: relief_proto::pb::Urgency::Now as i32,
            client_id: "metrics".into(),
            request_id: id,
            ..Default::default()
        };
        let mut stream = remote.request(request("sphere", 1)).await.expect("a request");
        while let Some(result) = stream.message().await.expect("results") {
            if result.r#final {
                break;
            }
        }
        assert!(remote.request(request("teapot", 2)).await.is_err());
    });
    let server = scrape(&python, &format!("http://{server_metrics}/metrics"));
    for (family, kind) in [
        ("relief_server_queue_depth", "gauge"),
        ("relief_server_jobs_in_flight", "gauge"),
        ("relief_server_workers", "gauge"),
        ("relief_server_worker_slots", "gauge"),
        ("relief_server_cache_bytes", "gauge"),
        ("relief_server_request_latency_seconds", "histogram"),
        ("relief_server_requests", "counter"),
        ("relief_server_cache_hits", "counter"),
        ("relief_server_results_discarded", "counter"),
        ("relief_server_requests_refused", "counter"),
    ] {
        assert_eq!(server[family]["type"], kind, "{family} in {server}");
    }
    assert_eq!(sample(&server, "relief_server_workers", &[]), 1.0);
    assert_eq!(sample(&server, "relief_server_requests_total", &[]), 1.0);
    assert_eq!(
        sample(&server, "relief_server_queue_depth", &[("urgency", "now")]),
        0.0
    );
    assert_eq!(
        sample(&server, "relief_server_request_latency_seconds_count", &[]),
        1.0
    );
    assert_eq!(
        sample(
            &server,
            "relief_server_request_latency_seconds_bucket",
            &[("le", "+Inf")]
        ),
        1.0
    );
    assert!(sample(&server, "relief_server_cache_bytes", &[]) > 0.0);
    let refused = [("reason", "invalid_argument")];
    assert_eq!(
        sample(&server, "relief_server_requests_refused_total", &refused),
        1.0
    );
    let worker = scrape(&python, &format!("http://{worker_metrics}/metrics"));
    assert_eq!(sample(&worker, "relief_worker_registered", &[]), 1.0);
    assert_eq!(
        sample(&worker, "relief_worker_bakes_total", &[("outcome", "finished")]),
        1.0
    );
    assert_eq!(sample(&worker, "relief_worker_rays_total", &[]), 64.0 * 64.0);
    assert_eq!(sample(&worker, "relief_worker_bake_seconds_count", &[]), 1.0);
    assert_eq!(sample(&worker, "relief_worker_jobs_running", &[]), 0.0);
}
