//! Wall-clock timing for the measurements: repeated runs after a warm-up, their median
//! or best. One definition for the benches, the report and `relief frame`.

use std::time::Instant;

use relief_core::stats::median;

/// Median wall time of `runs` calls of `f` (at least one), in milliseconds, after one
/// warm-up call.
pub fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    median_ms_after(runs, &mut (), |_| {}, |_| f())
}

/// As [`median_ms`] for calls on `state`, running the untimed `setup` on it before
/// each call.
pub fn median_ms_after<S>(
    runs: usize,
    state: &mut S,
    mut setup: impl FnMut(&mut S),
    mut f: impl FnMut(&mut S),
) -> f64 {
    setup(state);
    f(state);
    let times: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            setup(state);
            let start = Instant::now();
            f(state);
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    median(times)
}

/// Best wall time of `runs` calls of `f`, in milliseconds, after one warm-up call.
pub fn best_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    (0..runs.max(1))
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}
