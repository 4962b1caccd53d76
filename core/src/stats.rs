//! Summary statistics of measured samples, one definition for every report and
//! counter: median, percentiles by nearest rank, and the mean and minimum of the finite
//! values.

/// The median (the upper one for an even count); NaN for no values.
pub fn median(values: Vec<f64>) -> f64 {
    percentile(&values, 0.5)
}

/// The `p`-quantile (`p ∈ [0, 1]`) by nearest rank on the sorted values; NaN for none.
/// (Found by selection, without sorting: the server answers every client's look at its
/// counters with percentiles of 10,000 samples, holding its state's lock.)
pub fn percentile(values: &[f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut values = values.to_vec();
    let rank = nearest_rank(values.len(), p);
    *values.select_nth_unstable_by(rank, f64::total_cmp).1
}

/// The index of the `p`-quantile in `len` sorted values (`len > 0`).
fn nearest_rank(len: usize, p: f64) -> usize {
    ((len - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize
}

/// The mean of the finite values; `None` without any.
pub fn finite_mean(values: &[f64]) -> Option<f64> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    (!finite.is_empty()).then(|| finite.iter().sum::<f64>() / finite.len() as f64)
}

/// The median of the finite values (the upper one for an even count); `None` without
/// any.
pub fn finite_median(values: &[f64]) -> Option<f64> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    (!finite.is_empty()).then(|| median(finite))
}

/// The least of the finite values; `None` without any.
pub fn finite_min(values: &[f64]) -> Option<f64> {
    values.iter().copied().filter(|v| v.is_finite()).reduce(f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_by_nearest_rank() {
        let v = [5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(median(v.to_vec()), 3.0);
        assert_eq!(percentile(&v, 0.0), 1.0);
        assert_eq!(percentile(&v, 1.0), 5.0);
        assert_eq!(percentile(&v, 0.9), 5.0);
        assert_eq!(median(vec![1.0, 2.0]), 2.0, "the upper median");
        assert!(percentile(&[], 0.5).is_nan());
        assert_eq!(finite_mean(&[1.0, f64::INFINITY, 3.0]), Some(2.0));
        assert_eq!(finite_min(&[f64::NAN, 4.0, 2.0]), Some(2.0));
        assert_eq!(finite_mean(&[f64::NAN]), None);
        assert_eq!(
            finite_median(&[f64::INFINITY, 3.0, f64::NAN, 1.0, 2.0]),
            Some(2.0)
        );
        assert_eq!(finite_median(&[f64::NAN]), None);
    }

    /// Selection gives what sorting gives, at every rank, ties and NaN included.
    #[test]
    fn selection_agrees_with_the_sorted_values() {
        // (A fixed linear congruential sequence: many ties, some NaN.)
        let mut x: u64 = 12345;
        let values: Vec<f64> = (0..1001)
            .map(|_| {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                match x >> 58 {
                    0 => f64::NAN,
                    k => (k % 17) as f64 - 3.5,
                }
            })
            .collect();
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for k in 0..=100 {
            let p = k as f64 / 100.0;
            let (selected, expected) = (percentile(&values, p), sorted[nearest_rank(sorted.len(), p)]);
            assert_eq!(selected.to_bits(), expected.to_bits(), "p = {p}");
        }
    }
}
