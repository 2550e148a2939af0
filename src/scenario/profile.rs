//! Hand force profiles: smooth impacts, or samples from a CSV file.

use std::path::Path;

use serde::Deserialize;

/// One impact: raised-cosine rise, plateau, raised-cosine fall (C¹, so the preview sees no
/// artificial jerk spikes).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Impact {
    pub start: f64,
    pub rise: f64,
    #[serde(default)]
    pub hold: f64,
    pub fall: f64,
    pub force: [f64; 3],
}

impl Impact {
    pub(crate) fn validate(&self) -> Result<(), String> {
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        if !(ok(self.start)
            && ok(self.hold)
            && self.rise.is_finite()
            && self.rise > 0.0
            && self.fall.is_finite()
            && self.fall > 0.0)
        {
            return Err("start, hold must be ≥ 0 and rise, fall > 0 (s)".into());
        }
        if self.force.iter().any(|v| !v.is_finite()) {
            return Err("force must be finite".into());
        }
        Ok(())
    }

    /// How long the impact lasts (s): rise, hold and fall.
    pub fn length(&self) -> f64 {
        self.rise + self.hold + self.fall
    }

    /// The impact's envelope in [0, 1] at time t.
    pub(crate) fn envelope(&self, t: f64) -> f64 {
        let tau = t - self.start;
        let (r, h, f) = (self.rise, self.hold, self.fall);
        if tau <= 0.0 || tau >= self.length() {
            0.0
        } else if tau < r {
            0.5 * (1.0 - (std::f64::consts::PI * tau / r).cos())
        } else if tau <= r + h {
            1.0
        } else {
            0.5 * (1.0 + (std::f64::consts::PI * (tau - r - h) / f).cos())
        }
    }
}

/// The force the door applies on the hand over time (N, feet frame).
#[derive(Debug, Clone)]
pub enum ForceProfile {
    /// A sum of impacts.
    Impacts(Vec<Impact>),
    /// Samples (t, F) sorted by time, linearly interpolated, zero outside.
    Samples(Vec<(f64, [f64; 3])>),
}

impl ForceProfile {
    pub fn at(&self, t: f64) -> [f64; 3] {
        match self {
            ForceProfile::Impacts(impacts) => {
                let mut f = [0.0; 3];
                for imp in impacts {
                    let e = imp.envelope(t);
                    for c in 0..3 {
                        f[c] += e * imp.force[c];
                    }
                }
                f
            }
            ForceProfile::Samples(s) => {
                let i = s.partition_point(|(ts, _)| *ts <= t);
                if i == 0 || i == s.len() {
                    return [0.0; 3];
                }
                let ((t0, f0), (t1, f1)) = (s[i - 1], s[i]);
                let w = (t - t0) / (t1 - t0);
                [0, 1, 2].map(|c| f0[c] + w * (f1[c] - f0[c]))
            }
        }
    }

    /// The time from which the force is zero for good (s): the last impact's end, or the last
    /// sample's time.
    pub fn end(&self) -> f64 {
        match self {
            ForceProfile::Impacts(impacts) => impacts
                .iter()
                .map(|i| i.start + i.length())
                .fold(0.0, f64::max),
            ForceProfile::Samples(s) => s.last().map_or(0.0, |(t, _)| *t),
        }
    }

    /// The profile at `k·dt`, k = 0 … n−1: equal, bit for bit, to [`Self::at`] at each time, in
    /// O(n + the impacts' samples) rather than O(n × impacts) (an hour's soak scenario has
    /// 1800 impacts and 3.6 million samples).
    pub fn sampled(&self, dt: f64, n: usize) -> Vec<[f64; 3]> {
        match self {
            ForceProfile::Impacts(impacts) => {
                let mut out = vec![[0.0; 3]; n];
                for imp in impacts {
                    // The envelope is exactly 0 outside (start, start + duration), and adding
                    // 0 leaves a sum's bits as they are: only the samples inside are visited.
                    let end = imp.start + imp.rise + imp.hold + imp.fall;
                    let first = ((imp.start / dt).floor().max(0.0) as usize).min(n);
                    let last = ((end / dt).ceil().max(0.0) as usize + 1).min(n);
                    for (k, f) in out.iter_mut().enumerate().take(last).skip(first) {
                        let e = imp.envelope(k as f64 * dt);
                        for c in 0..3 {
                            f[c] += e * imp.force[c];
                        }
                    }
                }
                out
            }
            ForceProfile::Samples(_) => (0..n).map(|k| self.at(k as f64 * dt)).collect(),
        }
    }

    /// The profile with every force multiplied by `s`.
    pub fn scaled(&self, s: f64) -> ForceProfile {
        match self {
            ForceProfile::Impacts(impacts) => ForceProfile::Impacts(
                impacts
                    .iter()
                    .map(|i| Impact {
                        force: i.force.map(|f| f * s),
                        ..i.clone()
                    })
                    .collect(),
            ),
            ForceProfile::Samples(samples) => ForceProfile::Samples(
                samples
                    .iter()
                    .map(|(t, f)| (*t, f.map(|x| x * s)))
                    .collect(),
            ),
        }
    }

    /// Feed the profile's defining numbers (bit patterns, in order) to `h`: equal profiles give
    /// equal hashes on every machine, so processes can tell whether they play the same one.
    pub fn hash_into(&self, h: &mut super::ContentHash) {
        match self {
            ForceProfile::Impacts(impacts) => {
                h.u64(1);
                for i in impacts {
                    for v in [i.start, i.rise, i.hold, i.fall] {
                        h.f64(v);
                    }
                    for v in i.force {
                        h.f64(v);
                    }
                }
            }
            ForceProfile::Samples(s) => {
                h.u64(2);
                for (t, f) in s {
                    h.f64(*t);
                    for v in f {
                        h.f64(*v);
                    }
                }
            }
        }
    }

    /// Fill `out[i]` with the force at `t0 + i·dt`.
    pub fn sample_into(&self, t0: f64, dt: f64, out: &mut [[f64; 3]]) {
        for (i, f) in out.iter_mut().enumerate() {
            *f = self.at(t0 + i as f64 * dt);
        }
    }

    /// Read `t,fx,fy,fz` rows (a header line is allowed; `#` starts a comment).
    pub fn from_csv(path: &Path) -> Result<ForceProfile, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Self::parse_csv(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn parse_csv(text: &str) -> Result<ForceProfile, String> {
        let mut samples: Vec<(f64, [f64; 3])> = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            let nums: Result<Vec<f64>, _> = fields.iter().map(|f| f.parse::<f64>()).collect();
            let nums = match nums {
                Ok(v) => v,
                Err(_) if samples.is_empty() && n == 0 => continue, // header
                Err(_) => return Err(format!("line {}: expected numbers t,fx,fy,fz", n + 1)),
            };
            if nums.len() != 4 || nums.iter().any(|v| !v.is_finite()) {
                return Err(format!(
                    "line {}: expected 4 finite values t,fx,fy,fz",
                    n + 1
                ));
            }
            if let Some((tp, _)) = samples.last()
                && nums[0] <= *tp
            {
                return Err(format!(
                    "line {}: time {} does not increase",
                    n + 1,
                    nums[0]
                ));
            }
            samples.push((nums[0], [nums[1], nums[2], nums[3]]));
        }
        if samples.len() < 2 {
            return Err("needs at least two samples".into());
        }
        Ok(ForceProfile::Samples(samples))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid sampling gives `at`'s bits at every sample, for overlapping impacts (the soak's
    /// repeated pushes) and for samples.
    #[test]
    fn sampled_is_at_on_the_grid_bit_for_bit() {
        let impacts: Vec<Impact> = (0..40)
            .map(|k| Impact {
                start: 0.37 * k as f64,
                rise: 0.2 + 0.01 * k as f64,
                hold: if k % 3 == 0 { 0.1 } else { 0.0 },
                fall: 0.45,
                force: [-30.0 + k as f64, 2.5, -(k as f64) * 0.3],
            })
            .collect();
        let samples = ForceProfile::Samples(vec![(0.1, [1.0, -2.0, 0.5]), (3.3, [-4.0, 0.0, 7.0])]);
        for p in [ForceProfile::Impacts(impacts), samples] {
            let (dt, n) = (0.001, 16_000);
            let grid = p.sampled(dt, n);
            assert_eq!(grid.len(), n);
            for (k, f) in grid.iter().enumerate() {
                let want = p.at(k as f64 * dt);
                assert_eq!(f.map(f64::to_bits), want.map(f64::to_bits), "sample {k}");
            }
        }
    }
}
