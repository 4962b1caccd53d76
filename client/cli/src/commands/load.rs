//! `relief load`: many simulated clients flying the camera path against one server,
//! for each error tolerance (hence impostor lifetime): how request latency, stalls and
//! image error move. Writes `load.csv` and plots.

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use serde::Serialize;

use relief_client::flight::{Flight, FrameRecord, WARM_UP_LIMIT};
use relief_client::intake::Intake;
use relief_client::link::Link;
use relief_client::manager::{Config, Counters, Manager, late_fraction};
use relief_client::remote::Remote;
use relief_client::source::remote_manager;
use relief_core::scene::Scene;
use relief_core::stats::{finite_mean, finite_min, percentile};
use relief_lab::image_error::compare;
use relief_lab::plot::{Chart, Curve, register_font};
use relief_proto::bundle::bundle_for;
use relief_trace::{SceneTracer, render_reference};

use crate::processes::{LocalService, connect_and_upload};
use crate::{args, progress};

#[derive(Args)]
pub struct LoadArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// Simulated clients, each on its own place along the camera path; a list
    /// (comma-separated) runs each count in turn, to find where the workers saturate.
    #[arg(long, default_value = "8", value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=256))]
    clients: Vec<u32>,
    /// Tolerances (pixels of predicted gap growth) to run, comma-separated.
    #[arg(long, default_value = "4,8,16,32,64", value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::args::positive)]
    tolerances: Vec<f32>,
    /// Path frames each client flies per tolerance (the eye follows the clock, so a slow
    /// frame skips some).
    #[arg(long, default_value = "150", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    frames: u32,
    /// Camera pace.
    #[arg(long, default_value = "30", value_parser = clap::value_parser!(u32).range(1..=1000))]
    fps: u32,
    /// Workers to start for each run.
    #[arg(long, default_value = "2", value_parser = clap::value_parser!(u32).range(1..=64))]
    workers: u32,
    /// Network delay injected on the clients' side, milliseconds.
    #[arg(long, default_value = "0", value_parser = clap::value_parser!(u64).range(0..=60_000))]
    rtt_ms: u64,
    /// Frame size of the image-error samples (client 0 renders and compares).
    #[arg(long, default_value = "320x180", value_parser = args::frame_size)]
    size: (u32, u32),
    /// Client 0 compares with the ray-traced reference every K-th frame.
    #[arg(long, default_value = "25", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    reference_every: u32,
    /// Times each point is measured, each with a fresh server and workers: its figures
    /// pool them all, and the p99 latency's spread over them says how stable it is.
    #[arg(long, default_value = "3", value_parser = clap::value_parser!(u32).range(1..=100))]
    repeats: u32,
    /// Output directory: load.csv, load_latency.png, load_stalls.png.
    #[arg(long, default_value = "out/load")]
    out: PathBuf,
    /// Print the rows as a JSON array.
    #[arg(long)]
    json: bool,
}

/// One tolerance's results: a CSV row.
#[derive(Serialize, Clone)]
struct Row {
    tolerance_px: f32,
    clients: u32,
    /// Runs pooled into this row.
    repeats: u32,
    frames: u64,
    requests_now: u64,
    requests_predicted: u64,
    requests_per_s: f64,
    latency_ms_p50: f64,
    latency_ms_p99: f64,
    /// The least and the greatest p99 latency of one run: how far apart the repeats
    /// came out.
    latency_ms_p99_lo: f64,
    latency_ms_p99_hi: f64,
    /// The p99 latency of the requests needed now (a frame waits on them).
    latency_now_ms_p99: f64,
    /// Of the predictions answered, the fraction whose texture came after the time it
    /// was predicted to be needed, and the p99 of that lateness (negative: early).
    predictions_late_frac: f64,
    prediction_lateness_ms_p99: f64,
    /// Fraction of client frames with an impostor beyond tolerance or missing.
    stall_frac: f64,
    /// Final textures received per client per second of flight.
    textures_per_client_s: f64,
    /// Seconds from a final texture's arrival to the last frame it was shown in, all
    /// clients: the impostors' lifetime.
    lifetime_s_p10: f64,
    lifetime_s_p50: f64,
    psnr_db_mean: f64,
    psnr_db_min: f64,
    /// Predictions the saturated server refused.
    requests_shed: u64,
    /// Of the requests the server took in, the fraction a texture made for another eye
    /// (asked by another client, or another placement) served: work sharing saved.
    served_nearby_frac: f64,
    /// The mean factor the server's load put on the tolerance, over the frames: how
    /// much longer the textures were let live than asked.
    load_scale_mean: f64,
    /// The same of the link's factor (1 on 127.0.0.1; see
    /// [`Manager::link_scale`](relief_client::manager::Manager::link_scale)). In
    /// `--json` only.
    link_scale_mean: f64,
    /// Second by second of the flights (all clients, all runs): the frames, the share
    /// stalled and the share missing a texture, the load's factor on the tolerance, the
    /// server's load as heard, the textures asked for, the final textures that arrived
    /// and their round trips, the time deciding — whether a stall is a transient or the
    /// load's steady state, and whether its delay was the server's queue. In `--json`
    /// only.
    by_second: Vec<SecondOfLoad>,
}

/// One second of a load run's flights, pooled over clients and runs (a second none flew
/// in is empty: its shares and means NaN, `null` in JSON).
#[derive(Debug, Clone, Copy, Default, Serialize)]
struct SecondOfLoad {
    /// Frames flown in the second, by all clients of all runs.
    frames: u64,
    /// The share of them stalled.
    stall_frac: f64,
    /// Their mean factor of the server's load on the tolerance.
    load_scale_mean: f64,
    /// Their mean of the server's load as last heard
    /// ([`Manager::server_wait`](relief_client::manager::Manager::server_wait)), ms.
    server_wait_ms_mean: f64,
    /// Textures asked for in the second, by all clients of all runs.
    requests: u64,
    /// The share of its frames with an object that had no texture to warp (stalled
    /// for want of one, not for one past the tolerance).
    missing_frac: f64,
    /// Final textures taken in during the second …
    arrived: u64,
    /// … and their mean round trip, request sent to arrival, ms (NaN, null in JSON,
    /// when none came): a stall with the server's wait at zero and this long is a
    /// delay outside its queue.
    arrival_ms_mean: f64,
    /// The frames' mean time deciding (`FrameRecord::plan_ms`): the clients' own work,
    /// on the cores the workers bake on.
    plan_ms_mean: f64,
}

const HEADER: &str = "tolerance_px,clients,repeats,frames,requests_now,requests_predicted,requests_per_s,latency_ms_p50,latency_ms_p99,latency_ms_p99_lo,latency_ms_p99_hi,latency_now_ms_p99,predictions_late_frac,prediction_lateness_ms_p99,stall_frac,textures_per_client_s,lifetime_s_p10,lifetime_s_p50,psnr_db_mean,psnr_db_min,requests_shed,served_nearby_frac,load_scale_mean";

impl Row {
    fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{:.2},{:.2},{:.2},{:.2},{:.2},{:.2},{:.4},{:.2},{:.4},{:.3},{:.3},{:.3},{:.2},{:.2},{},{:.3},{:.2}",
            self.tolerance_px,
            self.clients,
            self.repeats,
            self.frames,
            self.requests_now,
            self.requests_predicted,
            self.requests_per_s,
            self.latency_ms_p50,
            self.latency_ms_p99,
            self.latency_ms_p99_lo,
            self.latency_ms_p99_hi,
            self.latency_now_ms_p99,
            self.predictions_late_frac,
            self.prediction_lateness_ms_p99,
            self.stall_frac,
            self.textures_per_client_s,
            self.lifetime_s_p10,
            self.lifetime_s_p50,
            self.psnr_db_mean,
            self.psnr_db_min,
            self.requests_shed,
            self.served_nearby_frac,
            self.load_scale_mean
        )
    }
}

/// What one simulated client brings back.
struct ClientResult {
    /// Frames drawn (path frames a slow frame skipped are not).
    frames: u32,
    counters: Counters,
    received: u64,
    /// Its final textures' lifetimes, seconds.
    lifetimes_s: Vec<f64>,
    psnr: Vec<f64>,
    /// Per frame flown: what its manager did and heard.
    records: Vec<FrameRecord>,
}

pub fn run(args: LoadArgs) -> Result<()> {
    // (Each is positive: `args::positive` parsed it, and the counts' parser too.)
    if args.tolerances.is_empty() || args.clients.is_empty() {
        bail!("--tolerances and --clients must each list at least one number");
    }
    let scene = Arc::new(crate::args::load_scene(&args.scene)?);
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let setup = Setup {
        tracer: Arc::new(SceneTracer::new(&scene)),
        bundle: Arc::new(bundle_for(&args.scene)?),
        scene,
        runtime: tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()?,
        args: &args,
    };
    let points = args.clients.len() * args.tolerances.len();
    let bar = progress::bar((points * args.repeats as usize) as u64, "load runs");
    let mut rows = Vec::new();
    for &clients in &args.clients {
        for &tolerance in &args.tolerances {
            let mut runs = Vec::new();
            for repeat in 1..=args.repeats {
                bar.set_message(format!(
                    "{clients} clients, tolerance {tolerance} px, run {repeat} of {}",
                    args.repeats
                ));
                runs.push(setup.measure(clients, tolerance)?);
                bar.inc(1);
            }
            rows.push(pooled(clients, tolerance, &runs));
        }
    }
    bar.finish_and_clear();
    let mut csv = String::from(HEADER) + "\n";
    for row in &rows {
        csv += &row.csv();
        csv.push('\n');
    }
    std::fs::write(args.out.join("load.csv"), csv).context("writing load.csv")?;
    register_font()?;
    // Each curve one client count, through its tolerances (points named by them),
    // against the impostors' lifetime those tolerances gave.
    let curves = |value: &dyn Fn(&Row) -> f64, what: &str| -> BTreeMap<String, Curve> {
        let mut curves: BTreeMap<String, Curve> = BTreeMap::new();
        for row in &rows {
            let (x, y) = (row.lifetime_s_p50, value(row));
            if x.is_finite() && x > 0.0 && y.is_finite() {
                let name = match row.clients {
                    1 => format!("  1 client{what}"),
                    n => format!("{n:>3} clients{what}"),
                };
                curves
                    .entry(name)
                    .or_default()
                    .insert((row.tolerance_px * 1000.0) as i64, (x, y));
            }
        }
        curves
    };
    let tolerance_label = |key: i64| Some(format!("{} px", key as f64 / 1000.0));
    let title = format!(
        "{} workers, RTT +{} ms; points: tolerance",
        args.workers, args.rtt_ms
    );
    let draw = |what: &str, y_desc: &str, file: &str, log_y: bool, curves: &BTreeMap<String, Curve>| {
        Chart {
            title: &format!("{what} vs impostor lifetime ({title})"),
            x_desc: "impostor lifetime, p50 (s): arrival to the last frame shown",
            y_desc,
            log_x: false,
            log_y,
            colour: &|_| None,
            point_label: &tolerance_label,
        }
        .draw(&args.out.join(file), curves)
    };
    let mut latency = curves(&|r| r.latency_ms_p50, ", p50");
    latency.extend(curves(&|r| r.latency_ms_p99, ", p99"));
    draw(
        "Request latency",
        "request latency (ms, log)",
        "load_latency.png",
        true,
        &latency,
    )?;
    let mut stalls = curves(&|r| 100.0 * r.stall_frac, ": stalled frames (%)");
    stalls.extend(curves(&|r| r.psnr_db_mean, ": PSNR mean (dB)"));
    draw(
        "Stalls and image error",
        "stalled frames (%) · PSNR (dB)",
        "load_stalls.png",
        false,
        &stalls,
    )?;
    if args.json {
        println!("{}", serde_json::to_string(&rows)?);
    } else {
        println!("{HEADER}");
        for row in &rows {
            println!("{}", row.csv());
        }
    }
    Ok(())
}

/// What every measured point shares.
struct Setup<'a> {
    scene: Arc<Scene>,
    tracer: Arc<SceneTracer>,
    bundle: Arc<relief_proto::bundle::Bundle>,
    runtime: tokio::runtime::Runtime,
    args: &'a LoadArgs,
}

impl Setup<'_> {
    /// One run of a point: a fresh server and workers, `clients` clients flying at
    /// `tolerance`.
    fn measure(&self, clients: u32, tolerance: f32) -> Result<Run> {
        let args = self.args;
        let path_frames = self.scene.path.frame_count().max(1);
        let service = LocalService::start(&args.out, args.workers)?;
        let (remote, hash) = self.runtime.block_on(connect_and_upload(
            &service.url,
            None,
            None,
            "load",
            &self.bundle,
            Some(args.workers),
        ))?;
        // Each client on a connection of its own, as clients on their own machines
        // are: on one shared connection, a keepalive ping answered late on the loaded
        // machine broke every client's streams at once.
        let remotes = (0..clients)
            .map(|c| {
                self.runtime
                    .block_on(Remote::connect(&service.url, None, &format!("load-{c}")))
                    .map_err(|e| anyhow!("simulated client {c}: {e}"))
            })
            .collect::<Result<Vec<_>>>()?;
        let line = Arc::new(StartLine::new(clients));
        let mut stats_remote = remote.clone();
        // One process, one intake: a texture many clients receive is made ready once (see
        // `relief_client::intake`), so the clients' own work stays off the workers' cores.
        let intake = Intake::default();
        let handles: Vec<_> = remotes
            .into_iter()
            .enumerate()
            .map(|(c, remote)| {
                let c = c as u32;
                // (No object drawn as geometry in a texture's stead: a stalled frame is
                // one whose textures did not come, whatever the frame could afford.)
                let config = Config {
                    tolerance,
                    stand_in_triangles: 0,
                    ..Config::default()
                };
                let mut manager = {
                    let _guard = self.runtime.enter();
                    remote_manager(
                        &self.scene,
                        config,
                        Link::new(remote, self.bundle.clone(), hash),
                        Duration::from_millis(args.rtt_ms),
                        intake.clone(),
                    )
                };
                let scene = self.scene.clone();
                let tracer = self.tracer.clone();
                let (frames, fps, size, every) = (args.frames, args.fps, args.size, args.reference_every);
                let start = c * path_frames / clients;
                let line = line.clone();
                std::thread::spawn(move || {
                    let flight = Flight {
                        scene: &scene,
                        size,
                        fps,
                        frames,
                        start,
                        wrap: true,
                    };
                    fly(&flight, &tracer, &mut manager, &line, c, every)
                })
            })
            .collect();
        let results: Vec<ClientResult> = handles
            .into_iter()
            .map(|h| {
                h.join()
                    .map_err(|_| anyhow!("a simulated client panicked"))
                    .and_then(|r| r)
            })
            .collect::<Result<_>>()?;
        let seconds = line.started().elapsed().as_secs_f64();
        // (The clients' figures stand without the server's counters: a failed look
        // costs only `served_nearby_frac`.)
        let served = match self.runtime.block_on(stats_remote.stats()) {
            Ok(stats) => {
                tracing::debug!(clients, tolerance, ?stats, "the server's counters after the run");
                Some((stats.served_nearby, stats.requests))
            }
            Err(e) => {
                tracing::warn!("the server's counters after the run: {}", e.message());
                None
            }
        };
        drop(service);
        Ok(Run {
            results,
            seconds,
            served,
        })
    }
}

/// Where the simulated clients wait for each other after their warm-ups, so that their
/// flights, and the figures, start together: a client flying while others still warmed
/// up met their cold starts' requests (every object in view at once, at full size) in
/// the queue and counted those waits and stalls as the load's — with 8 clients, most of
/// a run's stalled frames when the clients' first views held few objects.
struct StartLine {
    /// Clients arrived, and when the last did (or the line gave up waiting).
    state: Mutex<(u32, Option<Instant>)>,
    all_there: Condvar,
    clients: u32,
    /// When the line gives up waiting: [`START_LINE_LIMIT`] after it was drawn.
    deadline: Instant,
}

/// How long the line waits for the last client (one that panicked never comes; one
/// whose warm-up failed does): each warm-up gives up at [`WARM_UP_LIMIT`].
const START_LINE_LIMIT: Duration = WARM_UP_LIMIT.saturating_add(Duration::from_secs(10));

impl StartLine {
    fn new(clients: u32) -> StartLine {
        StartLine {
            state: Mutex::new((0, None)),
            all_there: Condvar::new(),
            clients,
            deadline: Instant::now() + START_LINE_LIMIT,
        }
    }

    /// Waits until every client has arrived, or the line's deadline has passed; then
    /// every client waiting goes at once.
    fn arrive(&self) {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        state.0 += 1;
        if state.0 >= self.clients {
            state.1.get_or_insert_with(Instant::now);
        }
        let left = self.deadline.saturating_duration_since(Instant::now());
        let (mut state, _) = (self.all_there)
            .wait_timeout_while(state, left, |s| s.1.is_none())
            .unwrap_or_else(PoisonError::into_inner);
        state.1.get_or_insert_with(Instant::now);
        self.all_there.notify_all();
    }

    /// When the flights started (now, if none has yet).
    fn started(&self) -> Instant {
        let state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        state.1.unwrap_or_else(Instant::now)
    }
}

/// One run of a point: what each client brought back, and how long the flight took.
struct Run {
    results: Vec<ClientResult>,
    seconds: f64,
    /// Of the requests the server took in, those a texture made for another eye
    /// served, and all of them (`None` when the server did not say).
    served: Option<(u64, u64)>,
}

/// The row of `clients` clients at `tolerance` from `runs`, pooled: counts summed, rates
/// over the runs' total time, percentiles over every run's samples.
fn pooled(clients: u32, tolerance: f32, runs: &[Run]) -> Row {
    let results = || runs.iter().flat_map(|run| &run.results);
    let seconds: f64 = runs.iter().map(|run| run.seconds).sum();
    let latencies: Vec<f64> = results()
        .flat_map(|r| r.counters.latencies_ms.iter().copied())
        .collect();
    let p99_of_runs: Vec<f64> = runs
        .iter()
        .map(|run| {
            let own: Vec<f64> = run
                .results
                .iter()
                .flat_map(|r| r.counters.latencies_ms.iter().copied())
                .collect();
            percentile(&own, 0.99)
        })
        .filter(|p| p.is_finite())
        .collect();
    let latencies_now: Vec<f64> = results()
        .flat_map(|r| r.counters.latencies_now_ms.iter().copied())
        .collect();
    let lateness: Vec<f64> = results()
        .flat_map(|r| r.counters.prediction_lateness_ms.iter().copied())
        .collect();
    let psnr: Vec<f64> = results().flat_map(|r| r.psnr.iter().copied()).collect();
    let lifetimes: Vec<f64> = results().flat_map(|r| r.lifetimes_s.iter().copied()).collect();
    let sum = |f: &dyn Fn(&ClientResult) -> u64| results().map(f).sum::<u64>();
    let (now, predicted) = (
        sum(&|r| r.counters.requests_now),
        sum(&|r| r.counters.requests_predicted),
    );
    let frames = sum(&|r| r.frames as u64);
    Row {
        tolerance_px: tolerance,
        clients,
        repeats: runs.len() as u32,
        frames,
        requests_now: now,
        requests_predicted: predicted,
        requests_per_s: (now + predicted) as f64 / seconds,
        latency_ms_p50: percentile(&latencies, 0.5),
        latency_ms_p99: percentile(&latencies, 0.99),
        latency_ms_p99_lo: p99_of_runs.iter().copied().reduce(f64::min).unwrap_or(f64::NAN),
        latency_ms_p99_hi: p99_of_runs.iter().copied().reduce(f64::max).unwrap_or(f64::NAN),
        latency_now_ms_p99: percentile(&latencies_now, 0.99),
        predictions_late_frac: late_fraction(&lateness),
        prediction_lateness_ms_p99: percentile(&lateness, 0.99),
        stall_frac: sum(&|r| r.counters.stale_frames) as f64 / frames as f64,
        // (Each run's clients flew for its time: client-seconds are clients × the total.)
        textures_per_client_s: sum(&|r| r.received) as f64 / (clients as f64 * seconds),
        lifetime_s_p10: percentile(&lifetimes, 0.1),
        lifetime_s_p50: percentile(&lifetimes, 0.5),
        // NaN (null in JSON) when no frame was compared.
        psnr_db_mean: finite_mean(&psnr).unwrap_or(f64::NAN),
        psnr_db_min: finite_min(&psnr).unwrap_or(f64::NAN),
        requests_shed: sum(&|r| r.counters.requests_shed),
        // NaN (null in JSON) when no server said.
        served_nearby_frac: {
            let said: Vec<(u64, u64)> = runs.iter().filter_map(|r| r.served).collect();
            let (nearby, all) = said.iter().fold((0, 0), |(n, a), &(x, y)| (n + x, a + y));
            if said.is_empty() {
                f64::NAN
            } else {
                nearby as f64 / all.max(1) as f64
            }
        },
        load_scale_mean: results().map(|r| r.counters.load_scale_sum).sum::<f64>() / frames.max(1) as f64,
        link_scale_mean: results().map(|r| r.counters.link_scale_sum).sum::<f64>() / frames.max(1) as f64,
        by_second: by_second(results().flat_map(|r| &r.records)),
    }
}

/// Frames' records pooled second by second of the flights.
fn by_second<'a>(records: impl Iterator<Item = &'a FrameRecord>) -> Vec<SecondOfLoad> {
    let mut seconds: Vec<SecondOfLoad> = Vec::new();
    for record in records {
        let second = record.at_s.max(0.0) as usize;
        if seconds.len() <= second {
            seconds.resize(second + 1, SecondOfLoad::default());
        }
        // (Sums here; shares and means below.)
        let s = &mut seconds[second];
        s.frames += 1;
        s.stall_frac += f64::from(u8::from(record.stale));
        s.load_scale_mean += f64::from(record.load_scale);
        s.server_wait_ms_mean += record.server_wait_ms;
        s.requests += record.requests;
        s.missing_frac += f64::from(u8::from(record.missing));
        s.arrived += u64::from(record.arrived);
        s.arrival_ms_mean += record.arrivals_ms_sum;
        s.plan_ms_mean += record.plan_ms;
    }
    for s in &mut seconds {
        let frames = s.frames as f64;
        s.stall_frac /= frames;
        s.missing_frac /= frames;
        s.arrival_ms_mean /= s.arrived as f64;
        s.plan_ms_mean /= frames;
        s.load_scale_mean /= frames;
        s.server_wait_ms_mean /= frames;
    }
    seconds
}

/// One simulated client: warms up, waits at `line` for the others, and flies
/// `flight`; client 0 also draws every `every`-th frame and compares it with the
/// ray-traced reference (a slow frame, which skips path frames as in the demo).
fn fly(
    flight: &Flight,
    tracer: &SceneTracer,
    manager: &mut Manager,
    line: &StartLine,
    client: u32,
    every: u32,
) -> Result<ClientResult> {
    let warmed = match flight.camera_at(0.0) {
        None => Err(anyhow!("the scene has no camera path")),
        Some(_) => flight.warm_up(manager).map_err(anyhow::Error::from),
    };
    // (At the line even when the warm-up failed: the others wait for every client.)
    line.arrive();
    warmed?;
    let mut psnr = Vec::new();
    let log = flight.fly(
        manager,
        |index| client == 0 && index.is_multiple_of(every),
        |flown| -> Result<ControlFlow<()>> {
            if let Some(image) = &flown.image {
                psnr.push(compare(image, &render_reference(tracer, flown.camera, 1), None).psnr_db);
            }
            Ok(ControlFlow::Continue(()))
        },
    )?;
    let received = (0..flight.scene.objects.len()).map(|k| manager.received(k)).sum();
    Ok(ClientResult {
        records: log.records,
        frames: log.frames,
        counters: manager.counters.clone(),
        received,
        lifetimes_s: manager.texture_lifetimes().seconds,
        psnr,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Clients arriving at the line one after another all leave once the last has
    /// arrived, not before, and the flights' start is then.
    #[test]
    fn the_clients_leave_the_start_line_together_once_all_are_there() {
        let line = Arc::new(StartLine::new(4));
        let arrivals: Vec<_> = (0..4u64)
            .map(|c| {
                let line = line.clone();
                std::thread::spawn(move || {
                    std::thread::sleep(Duration::from_millis(40 * c));
                    let arrived = Instant::now();
                    line.arrive();
                    (arrived, Instant::now())
                })
            })
            .collect();
        let times: Vec<(Instant, Instant)> = arrivals.into_iter().map(|h| h.join().unwrap()).collect();
        let last = times.iter().map(|t| t.0).max().unwrap();
        assert!(times.iter().all(|&(_, left)| left >= last));
        assert!(line.started() >= last && line.started() <= times.iter().map(|t| t.1).min().unwrap());
    }

    /// Frames land in the second they were flown in, whichever client flew them: each
    /// second's shares and means are its own frames', its counts their sums, and a
    /// second none flew in is empty (its shares and means NaN).
    #[test]
    fn a_flight_is_told_second_by_second() {
        let frame = |at_s, stale, load_scale, server_wait_ms, requests| FrameRecord {
            at_s,
            stale,
            load_scale,
            server_wait_ms,
            requests,
            // (Each frame deciding for a tenth of its second, in ms.)
            plan_ms: at_s * 10.0,
            ..FrameRecord::default()
        };
        // (One frame missing an object's texture; textures taken in, with their round trips.)
        let records = [
            frame(0.1, false, 1.0, 0.0, 2),
            FrameRecord {
                missing: true,
                arrived: 2,
                arrivals_ms_sum: 300.0,
                ..frame(0.9, true, 2.0, 300.0, 0)
            },
            frame(1.5, true, 4.0, 500.0, 1),
            frame(3.2, false, 1.0, 0.0, 0),
            FrameRecord {
                arrived: 1,
                arrivals_ms_sum: 600.0,
                ..frame(0.5, false, 3.0, 600.0, 1)
            },
        ];
        let seconds = by_second(records.iter());
        assert_eq!(seconds.len(), 4);
        let told = |s: &SecondOfLoad| {
            (
                s.frames,
                s.stall_frac,
                s.load_scale_mean,
                s.server_wait_ms_mean,
                s.requests,
                s.missing_frac,
                s.arrived,
            )
        };
        assert_eq!(told(&seconds[0]), (3, 1.0 / 3.0, 2.0, 300.0, 3, 1.0 / 3.0, 3));
        assert_eq!(seconds[0].arrival_ms_mean, 300.0);
        assert_eq!(told(&seconds[1]), (1, 1.0, 4.0, 500.0, 1, 0.0, 0));
        assert!(seconds[1].arrival_ms_mean.is_nan(), "no arrival, no mean");
        assert!(
            (seconds[0].plan_ms_mean - 5.0).abs() < 1e-9,
            "{}",
            seconds[0].plan_ms_mean
        );
        assert_eq!(told(&seconds[3]), (1, 0.0, 1.0, 0.0, 0, 0.0, 0));
        let empty = seconds[2];
        assert_eq!((empty.frames, empty.requests, empty.arrived), (0, 0, 0));
        assert!(
            empty.stall_frac.is_nan()
                && empty.load_scale_mean.is_nan()
                && empty.server_wait_ms_mean.is_nan()
                && empty.missing_frac.is_nan()
                && empty.arrival_ms_mean.is_nan()
                && empty.plan_ms_mean.is_nan()
        );
        let json = serde_json::to_string(&empty).expect("json");
        assert!(json.contains(r#""load_scale_mean":null"#), "{json}");
    }
}
