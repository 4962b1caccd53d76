//! Summary statistics of measured samples, one definition for every report and
//! counter: median, percentiles by nearest rank, and the mean and minimum of the finite
//! values.

/// The median (the upper one for an even count); NaN for no values.
pub fn median(values: Vec<f64>) -> f64 {
    percentile(&values, 0.5)
}

/// The `p`-quantile (`p ∈ [0, 1]`) by nearest rank on the sorted values; NaN for none.
pub fn percentile(values: &[f64], p: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted_percentile(&sorted, p)
}

/// [`percentile`] of values already sorted in ascending order (several quantiles of
/// one set sort it once).
pub fn sorted_percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize]
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
}
