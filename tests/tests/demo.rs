//! The loopback demo end to end, short: server and workers as child processes on
//! 127.0.0.1, a camera flight, frames and a summary written.

use relief_tests::{relief, scratch};

#[test]
fn the_demo_flies_and_summarises() {
    let out = scratch("demo");
    let run = relief(&[
        "demo",
        "--frames",
        "45",
        "--size",
        "160x90",
        "--reference-every",
        "15",
        "--write-every",
        "15",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    for key in [
        "frames",
        "frame_ms_p50",
        "frame_ms_p95",
        "geometry_frame_ms_p50",
        "requests_now",
        "requests_predicted",
        "latency_ms_p50",
        "latency_ms_p99",
        "prediction_hits",
        "stale_frames",
        "regenerations_per_orbit",
        "psnr_db_mean",
        "psnr_db_min",
    ] {
        assert!(!summary[key].is_null(), "{key} missing from {summary}");
    }
    assert_eq!(summary["frames"], 45);
    assert!(
        summary["source"].as_str().unwrap().starts_with("server"),
        "{summary}"
    );
    assert!(summary["requests_now"].as_u64().unwrap() + summary["requests_predicted"].as_u64().unwrap() > 0);
    // Textures arrived and were used: the impostor frames look like the reference.
    assert!(summary["psnr_db_mean"].as_f64().unwrap() > 25.0, "{summary}");
    for frame in ["frame_00000.png", "frame_00015.png", "frame_00030.png"] {
        assert!(out.join(frame).is_file(), "{frame} not written");
    }
    // The JSON printed is the summary written.
    let printed: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(printed, summary);
}
