//! A flight through what an operator's day does to the service, with the real
//! processes on 127.0.0.1: the server killed and started again on its address, a
//! server without a worker. The client must find its way back, say what happened, and
//! count it.

use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use relief_client::remote::Remote;
use relief_proto::pb::StatsReply;
use relief_tests::relay::{Link, Relay};
use relief_tests::{command, scratch, start_server, start_server_at, start_worker, wait_for};

/// One flight at a time: each times recoveries and counts stale frames, which two
/// flights sharing the machine's cores would not give (a flight over a lossy link went
/// from none to 14 % of its frames stale beside the others).
static ONE_FLIGHT: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Requests the server has answered (each counted once in its latency histogram).
fn answered(stats: &StatsReply) -> u64 {
    stats.latency_counts.iter().sum()
}

/// A `relief demo` running: its stderr read as it comes, each line with the time it
/// came, and its stdout (the JSON summary) read to the end.
struct Flying {
    child: Child,
    lines: std::sync::mpsc::Receiver<(Instant, String)>,
    stdout: std::thread::JoinHandle<Vec<u8>>,
}

/// `relief demo` against `url`, `frames` long, its summary as JSON on stdout; `extra`
/// flags after the rest.
fn fly(url: &str, frames: u32, out: &std::path::Path, extra: &[&str]) -> Flying {
    fly_as(command("relief"), url, frames, out, extra)
}

/// [`fly`] with `relief` as `relief` (e.g. on another host).
fn fly_as(
    mut relief: std::process::Command,
    url: &str,
    frames: u32,
    out: &std::path::Path,
    extra: &[&str],
) -> Flying {
    use std::io::{BufRead, Read};
    let mut child = relief
        .args(["demo", "--server", url, "--frames", &frames.to_string()])
        .args([
            "--size",
            "320x180",
            "--reference-every",
            "0",
            "--write-every",
            "0",
            "--json",
        ])
        .arg("--out")
        .arg(out)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting relief demo");
    let stderr = child.stderr.take().expect("the demo's stderr");
    let mut stdout = child.stdout.take().expect("the demo's stdout");
    let (tx, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send((Instant::now(), line));
        }
    });
    let stdout = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = stdout.read_to_end(&mut bytes);
        bytes
    });
    Flying { child, lines, stdout }
}

/// The demo's exit status, summary and stderr lines (with the time each came), once
/// it ends.
///
/// # Panics
/// When it has not ended within `within`.
fn finish(
    mut flying: Flying,
    within: Duration,
) -> (
    std::process::ExitStatus,
    serde_json::Value,
    Vec<(Instant, String)>,
) {
    let status = relief_tests::wait_exit(&mut flying.child, within);
    let stdout = flying.stdout.join().expect("reading the demo's stdout");
    let lines: Vec<(Instant, String)> = flying.lines.iter().collect();
    let stderr = text(&lines);
    let summary =
        serde_json::from_slice(&stdout).unwrap_or_else(|e| panic!("no JSON summary ({e}); stderr: {stderr}"));
    (status, summary, lines)
}

/// Lines as one text.
fn text(lines: &[(Instant, String)]) -> String {
    lines
        .iter()
        .map(|(_, l)| l.as_str())
        .collect::<Vec<_>>()
        .join("\n")
}

/// How long after a restarted server is listening its first request may be answered:
/// the client's health poll, the scene uploaded again, a worker's redial and one bake
/// (measured here: 1.4–1.7 s; CI machines are slower and busier).
const RECOVERED_WITHIN: Duration = Duration::from_secs(8);

/// The server is killed mid-flight and started again on its address 1 s later, with
/// none of its scenes: the flying client notices, draws meanwhile without it, finds the
/// new server, uploads its scene again unasked, and is served by the worker that
/// redialled — its first answer within [`RECOVERED_WITHIN`] of the server's start —
/// and its summary counts the time it could not be served.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flight_recovers_from_a_server_restart() {
    let _flight = ONE_FLIGHT.lock().await;
    let (server, url) = start_server(&[]);
    let _worker = start_worker(&url, &[]);
    let mut watch = Remote::connect(&url, None, "watch").await.unwrap();
    wait_for(&mut watch, "a worker", |s| s.workers == 1).await;
    let out = scratch("restart");
    // 20 s at 30 fps: enough for the restart and the recovery.
    let demo = fly(&url, 600, &out, &["--max-stale-frac", "1"]);
    wait_for(&mut watch, "the flight's first textures", |s| answered(s) >= 2).await;
    drop(server);
    tokio::time::sleep(Duration::from_secs(1)).await;
    let address = url.strip_prefix("http://").unwrap();
    let (_server, url) = start_server_at(address, &[]);
    let back = Instant::now();
    let mut watch = Remote::connect(&url, None, "watch").await.unwrap();
    wait_for(&mut watch, "the first request answered again", |s| {
        answered(s) >= 1
    })
    .await;
    let recovered = back.elapsed();
    eprintln!("first answer {recovered:?} after the restarted server listened");
    assert!(recovered < RECOVERED_WITHIN, "{recovered:?}");
    let (status, summary, lines) = tokio::task::spawn_blocking(move || finish(demo, Duration::from_secs(60)))
        .await
        .unwrap();
    let stderr = text(&lines);
    assert!(status.success(), "{stderr}");
    assert!(stderr.contains("cannot be reached"), "{stderr}");
    assert!(stderr.contains("serves again"), "{stderr}");
    let degraded = summary["degraded_s"].as_f64().unwrap();
    assert!((0.1..15.0).contains(&degraded), "degraded_s {degraded}");
    // Requests after the restart were answered: the flight saw its scene again.
    assert!(answered(&watch.stats().await.unwrap()) >= 1);
    for key in ["requests_failed", "requests_timed_out", "requests_open_at_exit"] {
        assert!(summary[key].is_u64(), "{key}: {summary}");
    }
}

/// How long the partition lasts: longer than HTTP/2 keepalive takes to give a silent
/// connection up on either side (4 s), so both ends are left with none.
const CUT_FOR: Duration = Duration::from_secs(6);

/// How soon after the cut the client must say the server cannot be reached (the
/// target: 5 s; measured here 3.9–4.0 s: HTTP/2 keepalive's 2 s ping and 2 s wait, or
/// two looks at the server's counters unanswered; CI machines are slower and busier).
const NOTICED_WITHIN: Duration = Duration::from_secs(6);

/// How soon after the link heals a request of the flight must be answered again (the
/// target: 2 s; CI machines are slower and busier).
const FLOWING_WITHIN: Duration = Duration::from_secs(6);

/// What a partition did to a flight: its summary once it ended, how long after the cut
/// it said the server could not be reached, and how long after the link healed the
/// server answered a request again.
struct Partitioned {
    summary: serde_json::Value,
    noticed: Duration,
    flowing: Duration,
}

/// Cuts `relay` for [`CUT_FOR`] while `demo` flies, heals it, and waits until `watch`
/// (the server's counters) shows a request answered again; then lets the demo end
/// (within `within`), which must succeed and must have said the cut.
async fn partition(relay: &Relay, watch: &mut Remote, demo: Flying, within: Duration) -> Partitioned {
    relay.cut();
    let cut = Instant::now();
    tokio::time::sleep(CUT_FOR).await;
    let before = answered(&watch.stats().await.unwrap());
    relay.heal();
    let healed = Instant::now();
    wait_for(watch, "a request answered after the link healed", |s| {
        answered(s) > before
    })
    .await;
    let flowing = healed.elapsed();
    let (status, summary, lines) = tokio::task::spawn_blocking(move || finish(demo, within))
        .await
        .unwrap();
    let stderr = text(&lines);
    assert!(status.success(), "{stderr}");
    let noticed = lines
        .iter()
        .find(|(_, line)| line.contains("cannot be reached"))
        .map(|(at, _)| at.saturating_duration_since(cut))
        .unwrap_or_else(|| panic!("the cut was not noticed: {stderr}"));
    Partitioned {
        summary,
        noticed,
        flowing,
    }
}

/// The link between a flying client and its server is cut for [`CUT_FOR`] — a relay
/// that stops passing bytes and closes nothing, as a partition does: the client says
/// so within [`NOTICED_WITHIN`], draws meanwhile without the server, and is answered
/// again within [`FLOWING_WITHIN`] of the link's return.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_partition_is_noticed_and_healed() {
    let _flight = ONE_FLIGHT.lock().await;
    let (_server, url) = start_server(&[]);
    let _worker = start_worker(&url, &[]);
    let mut watch = Remote::connect(&url, None, "watch").await.unwrap();
    wait_for(&mut watch, "a worker", |s| s.workers == 1).await;
    let relay = Relay::start(url.strip_prefix("http://").unwrap(), Duration::ZERO).await;
    let out = scratch("partition");
    let demo = fly(&relay.url(), 600, &out, &["--max-stale-frac", "1"]);
    wait_for(&mut watch, "the flight's first textures", |s| answered(s) >= 2).await;
    let Partitioned {
        summary,
        noticed,
        flowing,
    } = partition(&relay, &mut watch, demo, Duration::from_secs(60)).await;
    eprintln!("cut noticed after {noticed:?}; answered again {flowing:?} after the link healed");
    assert!(noticed < NOTICED_WITHIN, "{noticed:?}");
    assert!(flowing < FLOWING_WITHIN, "{flowing:?}");
    let degraded = summary["degraded_s"].as_f64().unwrap();
    assert!(
        (1.0..CUT_FOR.as_secs_f64() + 5.0).contains(&degraded),
        "degraded_s {degraded}"
    );
}

/// A server without a worker: the client says so once, makes its textures itself (the
/// flight has impostors, not only geometry), counts the whole flight as degraded —
/// and a run whose frames went stale past `--max-stale-frac` exits with an error
/// naming it.
#[test]
fn a_server_without_workers_is_said_counted_and_can_fail_the_run() {
    let _flight = ONE_FLIGHT.blocking_lock();
    let (_server, url) = start_server(&[]);
    let out = scratch("no-workers");
    let (status, summary, lines) = finish(fly(&url, 60, &out, &[]), Duration::from_secs(120));
    let stderr = text(&lines);
    assert!(status.success(), "{stderr}");
    assert_eq!(stderr.matches("the server has no worker").count(), 1, "{stderr}");
    let degraded = summary["degraded_s"].as_f64().unwrap();
    assert!(degraded > 1.0, "degraded_s {degraded}");
    assert!(summary["warps"].as_u64().unwrap() > 0, "{summary}");
    // A tolerance nothing meets keeps frames stale (none drawn as geometry instead):
    // over a limit of 1 %, the run fails.
    let out = scratch("stale");
    let strict = [
        "--tolerance",
        "0.001",
        "--stand-in-triangles",
        "0",
        "--max-stale-frac",
        "0.01",
    ];
    let (status, _, lines) = finish(fly(&url, 60, &out, &strict), Duration::from_secs(120));
    let stderr = text(&lines);
    assert!(!status.success());
    assert!(stderr.contains("--max-stale-frac"), "{stderr}");
}

/// Each way's delay between hosts in [`a_flight_across_hosts_rides_out_a_partition`]:
/// a 100 ms round trip.
const HOST_DELAY: Duration = Duration::from_millis(50);

/// Server, worker and client each on a network stack of its own (namespaces, joined
/// only through relays this test runs; root needed, else skipped), the client 100 ms
/// of round trip away: a flight rides out a 6 s partition of its link — said within
/// [`NOTICED_WITHIN`], answered again within [`FLOWING_WITHIN`] of the link's return —
/// and its frames stay mostly fresh.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flight_across_hosts_rides_out_a_partition() {
    let _flight = ONE_FLIGHT.lock().await;
    let Some(hosts) = relief_tests::netns::Hosts::create("rlft", 77, 3) else {
        eprintln!("skipped: network namespaces need root (`ip netns add` failed)");
        return;
    };
    let (server_host, worker_host, client_host) = (1, 2, 3);
    let mut server = hosts.command(server_host, "relief-server");
    server.args(["--listen", &format!("{}:7411", hosts.address(server_host))]);
    let (_server, _) = relief_tests::spawn_server(server);
    let target = format!("{}:7411", hosts.address(server_host));
    let to_worker = Relay::start_on(
        &format!("{}:7411", hosts.gateway(worker_host)),
        &target,
        HOST_DELAY,
    )
    .await;
    let to_client = Relay::start_on(
        &format!("{}:7411", hosts.gateway(client_host)),
        &target,
        HOST_DELAY,
    )
    .await;
    let mut worker = hosts.command(worker_host, "relief-worker");
    worker.args(["--server", &to_worker.url(), "--heartbeat-ms", "250"]);
    let _worker = relief_tests::Running(worker.spawn().expect("starting the worker"));
    let mut watch = Remote::connect(&format!("http://{target}"), None, "watch")
        .await
        .unwrap();
    wait_for(&mut watch, "the worker", |s| s.workers == 1).await;
    let out = scratch("hosts");
    let relief = hosts.command(client_host, "relief");
    // (Stale frames counted whole: none drawn as geometry instead.)
    let fresh = ["--max-stale-frac", "1", "--stand-in-triangles", "0"];
    let demo = fly_as(relief, &to_client.url(), 600, &out, &fresh);
    wait_for(&mut watch, "the flight's first textures", |s| answered(s) >= 2).await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    let Partitioned {
        summary,
        noticed,
        flowing,
    } = partition(&to_client, &mut watch, demo, Duration::from_secs(90)).await;
    let (stale, frames) = (
        summary["stale_frames"].as_u64().unwrap(),
        summary["frames"].as_u64().unwrap(),
    );
    eprintln!(
        "across hosts, 100 ms round trip: cut noticed after {noticed:?}, answered {flowing:?} after healing; \
         {stale} of {frames} frames stale; latency p50 {} ms",
        summary["latency_ms_p50"]
    );
    assert!(noticed < NOTICED_WITHIN, "{noticed:?}");
    assert!(flowing < FLOWING_WITHIN, "{flowing:?}");
    // The partition's 6 s are a fifth of the flight; the rest stays fresh.
    assert!((stale as f64) < 0.4 * frames as f64, "{stale} of {frames}");
}

/// The link of [`a_flight_over_a_lossy_link_stays_fresh`]: a 100 ms round trip, 2 % of
/// segments lost.
const LOSSY: Link = Link {
    delay: Duration::from_millis(50),
    loss: 0.02,
};

/// The most of its frames a 20 s flight over [`LOSSY`] at [`LOSSY_TOLERANCE`] may show
/// stale (every object without a valid texture counted, none drawn as geometry in its
/// stead: `--stand-in-triangles 0`). The target is 2 %: run in this file after the
/// other tests, 0.0–1.8 % in 14 runs of the client as it is; 5.0 % in one of 14 before
/// an object's last glimpse was looked for from a typical round trip on (the rock,
/// passed close on the orbit while its answers took up to a second), and 0.0–9.0 % in 9
/// before that glimpse was planned for at all and an orbit was foreseen as a turn. (An
/// earlier 0–0.3 % over 10 s was the client taking the workers' round trip for
/// saturation, and letting its textures live 8× longer than asked all flight.) A
/// breakdown shows far above this: 35–49 % over 250 ms links. (Flying beside another
/// flight is kept out by `ONE_FLIGHT`.)
const LOSSY_STALE_AT_MOST: f64 = 0.10;

/// The tolerance the lossy flight asks for, pixels: the lifetime such a link affords
/// (twice the default; the bands past the rim, which scale with it, twice too).
/// Its textures come a p50 of 0.4 s after they are asked for (2 % loss holds a TCP
/// stream to a few hundred kB/s); at the default tolerance, half as long-lived, 4.7–10.8
/// % of the flight's frames were stale (3 runs).
const LOSSY_TOLERANCE: &str = "24";

/// A flight whose client and workers reach the server over [`LOSSY`] links, predicting
/// ahead: its textures come in time for most frames. The workers take two jobs at
/// once, as workers a round trip away should: one job's texture travels while the
/// next bakes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flight_over_a_lossy_link_stays_fresh() {
    let _flight = ONE_FLIGHT.lock().await;
    let (_server, url) = start_server(&[]);
    let target = url.strip_prefix("http://").unwrap();
    let to_workers = Relay::start_link("127.0.0.1:0", target, LOSSY).await;
    let _workers = [
        start_worker(&to_workers.url(), &["--slots", "2"]),
        start_worker(&to_workers.url(), &["--slots", "2"]),
    ];
    let mut watch = Remote::connect(&url, None, "watch").await.unwrap();
    wait_for(&mut watch, "two workers", |s| s.workers == 2).await;
    let to_client = Relay::start_link("127.0.0.1:0", target, LOSSY).await;
    let out = scratch("lossy");
    let demo = fly(
        &to_client.url(),
        600,
        &out,
        &[
            "--max-stale-frac",
            "1",
            "--tolerance",
            LOSSY_TOLERANCE,
            "--stand-in-triangles",
            "0",
        ],
    );
    let (status, summary, lines) = finish(demo, Duration::from_secs(120));
    // (Beside the summary, kept when the test fails: with
    // `RUST_LOG=relief_client::manager=debug`, why each stale frame was.)
    let log = text(&lines);
    std::fs::write(out.join("stderr.log"), &log).expect("writing the flight's log");
    assert!(status.success(), "{status}: {log}");
    let frames = summary["frames"].as_f64().unwrap();
    let stale = summary["stale_frames"].as_f64().unwrap() / frames;
    eprintln!(
        "over a 100 ms round trip with 2 % loss: {:.1} % of {frames} frames stale ({}), latency p50 {} ms, p99 {} ms",
        100.0 * stale,
        summary["stale_causes"],
        summary["latency_ms_p50"],
        summary["latency_ms_p99"]
    );
    assert!(stale <= LOSSY_STALE_AT_MOST, "{stale}");
}
