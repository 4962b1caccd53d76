//! `relief load` on 127.0.0.1: simulated clients per count and tolerance, each point
//! run twice and pooled into a CSV row, plots against the impostors' lifetime.

use relief_tests::{relief, scratch};

#[test]
fn load_runs_write_a_row_per_client_count_and_tolerance_and_plots() {
    let out = scratch("load");
    let run = relief(&[
        "load",
        "--clients",
        "1,2",
        "--tolerances",
        "8,64",
        "--frames",
        "20",
        "--size",
        "64x36",
        "--reference-every",
        "10",
        "--repeats",
        "2",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let rows: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let rows = rows.as_array().unwrap();
    // Each client count in turn, each through the tolerances.
    assert_eq!(rows.len(), 4);
    let requests = |row: &serde_json::Value| {
        row["requests_now"].as_u64().unwrap() + row["requests_predicted"].as_u64().unwrap()
    };
    for (row, (clients, tolerance)) in rows.iter().zip([(1, 8.0), (1, 64.0), (2, 8.0), (2, 64.0)]) {
        assert_eq!(row["clients"], clients, "{row}");
        assert_eq!(row["tolerance_px"].as_f64(), Some(tolerance), "{row}");
        // Frames drawn by all the clients in both runs: a slow frame skips path frames.
        assert_eq!(row["repeats"], 2, "{row}");
        let frames = row["frames"].as_u64().unwrap();
        assert!((20 * clients..=40 * clients).contains(&frames), "{row}");
        assert!(row.get("lifetime_s_p50").is_some(), "{row}");
    }
    // The tight tolerance needs new textures on this path; the loose one lives longer,
    // so it needs no more (on so short a path, often none: then no latency either).
    let (tight, loose) = (&rows[2], &rows[3]);
    assert_eq!(
        (tight["tolerance_px"].as_f64(), loose["tolerance_px"].as_f64()),
        (Some(8.0), Some(64.0))
    );
    assert!(requests(tight) > 0, "{tight}");
    assert!(tight["latency_ms_p50"].as_f64().unwrap() > 0.0, "{tight}");
    // The pooled p99 lies within the runs' own.
    let p99 = |key: &str| tight[key].as_f64().unwrap_or(f64::NAN);
    assert!(
        p99("latency_ms_p99_lo") <= p99("latency_ms_p99") + 1e-9
            && p99("latency_ms_p99") <= p99("latency_ms_p99_hi") + 1e-9,
        "{tight}"
    );
    assert!(requests(loose) <= requests(tight), "{loose} vs {tight}");
    let csv = std::fs::read_to_string(out.join("load.csv")).unwrap();
    assert_eq!(csv.lines().count(), 5, "{csv}");
    assert!(csv.starts_with("tolerance_px,clients,repeats,frames,"));
    for plot in ["load_latency.png", "load_stalls.png"] {
        assert!(out.join(plot).is_file(), "{plot} missing");
    }
}
