//! The Pareto front of (cost, error) points: the settings no other setting beats on both.

/// Whether each of `points` (cost, error) is Pareto-optimal: no other point has a cost and an
/// error at most its own with one of them smaller. Points with a non-finite coordinate are
/// never optimal and never dominate.
pub fn pareto_optimal(points: &[(f64, f64)]) -> Vec<bool> {
    let finite = |&(c, e): &(f64, f64)| c.is_finite() && e.is_finite();
    points
        .iter()
        .map(|p| {
            finite(p)
                && !points
                    .iter()
                    .filter(|q| finite(q))
                    .any(|q| q.0 <= p.0 && q.1 <= p.1 && (q.0 < p.0 || q.1 < p.1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn front_keeps_the_points_nothing_beats_on_both() {
        let points = [
            (1.0, 0.5),      // cheapest: optimal
            (2.0, 0.6),      // beaten by the first on both
            (4.0, 0.1),      // optimal
            (4.0, 0.2),      // same cost, larger error: beaten
            (8.0, 0.1),      // same error, costlier: beaten
            (16.0, 0.01),    // most accurate: optimal
            (0.5, f64::NAN), // no error (a failed run): never optimal
            (f64::NAN, 0.0), // and never beats anything
        ];
        assert_eq!(
            pareto_optimal(&points),
            [true, false, true, false, false, true, false, false]
        );
    }

    #[test]
    fn equal_points_are_both_optimal() {
        assert_eq!(pareto_optimal(&[(1.0, 0.1), (1.0, 0.1)]), [true, true]);
        assert!(pareto_optimal(&[]).is_empty());
    }
}
