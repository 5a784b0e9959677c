//! The human-readable summary of a bag's analysis (`sandstep analyze`).

use super::BagSummary;
use std::fmt;

/// Metres shown as millimetres in the human summary.
const MM_PER_M: f64 = 1e3;

/// `value` with `decimals` and `unit`, or `-` when absent.
fn or_dash(value: Option<f64>, decimals: usize, unit: &str) -> String {
    value.map_or("-".into(), |v| format!("{v:.decimals$} {unit}"))
}

impl fmt::Display for BagSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "bag: {}", self.bag)?;
        if self.start_s > 0.0 {
            writeln!(f, "analysed from t = {:.3} s on", self.start_s)?;
        }
        writeln!(
            f,
            "body pose from {}: {:.3} s, distance {:.4} m along x, mean speed {}",
            self.pose_source,
            self.duration_s,
            self.distance_m,
            or_dash(self.mean_speed_m_s, 4, "m/s")
        )?;
        writeln!(
            f,
            "  lateral drift {:.4} m, height mean {:.1} mm (min {:.1} mm), max tilt {:.2} deg",
            self.lateral_drift_m,
            MM_PER_M * self.body_height_mean_m,
            MM_PER_M * self.body_height_min_m,
            self.max_tilt_deg
        )?;
        match (&self.gait_joint, self.gait_cycles) {
            (Some(joint), Some(cycles)) => {
                writeln!(
                    f,
                    "gait: {cycles} complete cycles of {joint}, speed per cycle {} (std {})",
                    or_dash(self.speed_per_cycle_mean_m_s, 4, "m/s"),
                    or_dash(self.speed_per_cycle_std_m_s, 4, "m/s")
                )?;
                if !self.speed_per_cycle_m_s.is_empty() {
                    let speeds: Vec<String> = self
                        .speed_per_cycle_m_s
                        .iter()
                        .map(|v| format!("{v:.4}"))
                        .collect();
                    writeln!(f, "  per cycle (m/s): {}", speeds.join(" "))?;
                }
            }
            _ => writeln!(f, "gait: no joint states")?,
        }
        match (self.sand_level_m, self.sinkage_mean_m, self.sinkage_max_m) {
            (Some(level), Some(mean), Some(max)) => writeln!(
                f,
                "sinkage below the sand level ({:.1} mm): mean {:.2} mm, max {:.2} mm",
                MM_PER_M * level,
                MM_PER_M * mean,
                MM_PER_M * max
            )?,
            _ => writeln!(f, "sinkage: -")?,
        }
        if !self.leg_forces.is_empty() || self.body_force.is_some() {
            writeln!(
                f,
                "sand force per link: {:<23} {:>11} {:>11} {:>15}",
                "link", "mean |F| N", "peak |F| N", "mean vert. F N"
            )?;
            let body = self.body_force.iter().map(|force| ("body", force));
            let legs = self
                .leg_forces
                .iter()
                .map(|(leg, force)| (leg.as_str(), force));
            for (link, force) in body.chain(legs) {
                writeln!(
                    f,
                    "                     {link:<23} {:>11.4} {:>11.4} {:>15}",
                    force.mean_force_n,
                    force.peak_force_n,
                    force
                        .mean_vertical_force_n
                        .map_or("-".into(), |v| format!("{v:.4}"))
                )?;
            }
        }
        for (topic, command) in &self.commands {
            writeln!(
                f,
                "command {topic}: {} messages, first {}, last {}",
                command.count, command.first, command.last
            )?;
        }
        writeln!(f, "topics:")?;
        for topic in &self.topics {
            writeln!(
                f,
                "  {:<40} {:<36} {:>8}",
                topic.name, topic.type_name, topic.count
            )?;
        }
        for plot in &self.plots {
            writeln!(f, "plot: {plot}")?;
        }
        for note in &self.notes {
            writeln!(f, "note: {note}")?;
        }
        Ok(())
    }
}
