//! Gait cycles from a joint's unwrapped angle, and body speed per cycle and over time.

use std::f64::consts::TAU;

use serde::Serialize;

use super::tf::{pose_at, TimedPose};

/// An angle within this much (rad) of a multiple of 2π counts as on it.
const ON_TURN_EPSILON_RAD: f64 = 1e-9;

/// One complete gait cycle: the joint turned a full 2π between `start_s` and `end_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GaitCycle {
    /// Start time (s since the analysis origin).
    pub start_s: f64,
    /// End time (s).
    pub end_s: f64,
    /// Body displacement along x over the cycle divided by its duration (m/s).
    pub speed_m_s: f64,
}

/// Times (s) at which `angle` (rad, unwrapped; `(time s, angle)` sorted by time) crosses a
/// multiple of 2π, in either direction. A crossing counts only if it is at another multiple
/// than the previous one, so a joint that dithers around a multiple does not add cycles.
/// A first sample lying on a multiple is a boundary.
pub fn cycle_boundaries(angle: &[(f64, f64)]) -> Vec<f64> {
    let samples: Vec<(f64, f64)> = angle
        .iter()
        .copied()
        .filter(|(t, a)| t.is_finite() && a.is_finite())
        .collect();
    let mut boundaries = Vec::new();
    let Some(&(t_first, a_first)) = samples.first() else {
        return boundaries;
    };
    let mut last_turn: Option<i64> = None;
    let nearest_turn = (a_first / TAU).round();
    if (a_first - nearest_turn * TAU).abs() < ON_TURN_EPSILON_RAD {
        boundaries.push(t_first);
        last_turn = Some(nearest_turn as i64);
    }
    for pair in samples.windows(2) {
        let ((t0, a0), (t1, a1)) = (pair[0], pair[1]);
        let (k0, k1) = ((a0 / TAU).floor() as i64, (a1 / TAU).floor() as i64);
        // Multiples crossed, in the order the joint passed them.
        let crossed: Vec<i64> = if k1 > k0 {
            (k0 + 1..=k1).collect()
        } else {
            (k1 + 1..=k0).rev().collect()
        };
        for turn in crossed {
            if last_turn == Some(turn) {
                continue;
            }
            let s = (turn as f64 * TAU - a0) / (a1 - a0);
            boundaries.push(t0 + s * (t1 - t0));
            last_turn = Some(turn);
        }
    }
    boundaries
}

/// The complete cycles between consecutive `boundaries` (s) that lie within the pose samples,
/// each with its mean speed along x.
pub fn cycles(boundaries: &[f64], pose: &[TimedPose]) -> Vec<GaitCycle> {
    boundaries
        .windows(2)
        .filter_map(|b| {
            let (start_s, end_s) = (b[0], b[1]);
            let duration = end_s - start_s;
            if duration <= 0.0 {
                return None;
            }
            let x0 = pose_at(pose, start_s)?.translation.x;
            let x1 = pose_at(pose, end_s)?.translation.x;
            Some(GaitCycle {
                start_s,
                end_s,
                speed_m_s: (x1 - x0) / duration,
            })
        })
        .collect()
}

/// Speed along x over time: `(t, Δx/Δt)` over a window of `window_s` centred on each pose
/// sample whose window lies within the samples.
pub fn smoothed_speed(pose: &[TimedPose], window_s: f64) -> Vec<(f64, f64)> {
    let half = 0.5 * window_s;
    if window_s <= 0.0 {
        return Vec::new();
    }
    pose.iter()
        .filter_map(|(t, _)| {
            let x0 = pose_at(pose, t - half)?.translation.x;
            let x1 = pose_at(pose, t + half)?.translation.x;
            Some((*t, (x1 - x0) / window_s))
        })
        .collect()
}

/// Mean and population standard deviation; `None` for no values.
pub fn mean_and_std(values: &[f64]) -> Option<(f64, f64)> {
    if values.is_empty() {
        return None;
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    Some((mean, variance.sqrt()))
}

/// Mean and sample standard deviation (`n - 1` in the denominator; `None` below two values)
/// of values drawn independently, such as a quantity over starts; `None` for no values.
pub fn mean_and_sample_std(values: &[f64]) -> Option<(f64, Option<f64>)> {
    let (mean, _) = mean_and_std(values)?;
    let n = values.len() as f64;
    let squares = || values.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    Some((
        mean,
        (values.len() > 1).then(|| (squares() / (n - 1.0)).sqrt()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;

    #[test]
    fn sample_std_divides_by_n_minus_one() {
        let (mean, std) = mean_and_sample_std(&[0.1, 0.2, 0.3]).unwrap();
        assert!((mean - 0.2).abs() < 1e-15);
        assert!((std.unwrap() - 0.1).abs() < 1e-15);
        assert_eq!(mean_and_sample_std(&[0.5]), Some((0.5, None)));
        assert_eq!(mean_and_sample_std(&[]), None);
    }

    fn turning(frequency_hz: f64, duration_s: f64, rate_hz: f64) -> Vec<(f64, f64)> {
        let n = (duration_s * rate_hz).round() as usize;
        (0..=n)
            .map(|i| {
                let t = i as f64 / rate_hz;
                (t, TAU * frequency_hz * t)
            })
            .collect()
    }

    #[test]
    fn forward_and_backward_turns_make_boundaries() {
        // 3.01 s so that the crossing at 3 s is not left to rounding.
        let b = cycle_boundaries(&turning(2.0, 3.01, 100.0));
        assert_eq!(b.len(), 7, "{b:?}");
        for (i, t) in b.iter().enumerate() {
            assert!((t - 0.5 * i as f64).abs() < 1e-9, "{b:?}");
        }
        let backward: Vec<(f64, f64)> = turning(2.0, 3.01, 100.0)
            .into_iter()
            .map(|(t, a)| (t, 0.3 - a))
            .collect();
        assert_eq!(cycle_boundaries(&backward).len(), 6);
    }

    #[test]
    fn dithering_around_a_multiple_is_one_boundary() {
        let angle: Vec<(f64, f64)> = (0..100)
            .map(|i| {
                (
                    i as f64 * 0.01,
                    TAU + 0.01 * if i % 2 == 0 { 1.0 } else { -1.0 },
                )
            })
            .collect();
        assert_eq!(cycle_boundaries(&angle).len(), 1);
    }

    #[test]
    fn cycle_speed_is_displacement_over_duration() {
        let pose: Vec<TimedPose> = (0..=300)
            .map(|i| {
                let t = i as f64 * 0.01;
                (t, Isometry3::translation(0.1 * t, 0.0, 0.0))
            })
            .collect();
        let c = cycles(&[0.5, 1.0, 2.0, 3.5], &pose);
        assert_eq!(c.len(), 2, "the last cycle ends after the pose samples");
        assert!(c.iter().all(|c| (c.speed_m_s - 0.1).abs() < 1e-12));
        let v = smoothed_speed(&pose, 0.1);
        assert_eq!(v.len(), 301 - 10);
        assert!(v.iter().all(|(_, v)| (v - 0.1).abs() < 1e-9));
        let (mean, std) = mean_and_std(&[1.0, 3.0]).unwrap();
        assert_eq!((mean, std), (2.0, 1.0));
    }
}
