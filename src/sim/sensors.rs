//! What the robot's sensors make of the plant's truth (`[sim.sensors]`, docs/sensing.md): the
//! state a plant publishes passes through these models before it leaves, as a robot's SDK would
//! hand it over. Ground truth keeps going out on its own channel.
//!
//! Modelled: joint encoders (quantised positions; velocities from the drives with white noise),
//! the wrist force sensor and the sole forces (white noise, a constant bias, a bias drifting as
//! a random walk, resolution, latency in steps, dropped samples holding the previous one). Not
//! yet: the floating base (pose and velocity published as the plant's truth until the base
//! estimator replaces them) and an IMU.
//!
//! Reproducible: one seeded generator per plant run, drawn in a fixed order every step, so a
//! lockstep rerun publishes the same bytes. Allocation-free after [`Sensors::new`].

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use crate::channels::{MAX_DOF, N_CONTACTS, StateMsg};

/// Truth or the sensor models (`sim.sensors.sensing`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Sensing {
    /// The plant's state as it is.
    Truth,
    /// Through the sensor models below.
    Realistic,
}

impl Sensing {
    pub fn name(self) -> &'static str {
        match self {
            Sensing::Truth => "truth",
            Sensing::Realistic => "realistic",
        }
    }
}

/// One three-axis force sensor's model (per axis).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSensorConfig {
    /// σ of the white noise of one sample (N).
    pub noise: f64,
    /// Magnitude of the constant bias per axis (N); its signs are drawn from the seed.
    pub bias: f64,
    /// Bias random walk (N/√s): after t seconds the bias has wandered by drift·√t (1σ).
    pub drift: f64,
    /// Resolution (N): samples are rounded to a multiple of it (0: none).
    pub resolution: f64,
    /// Delay in plant steps.
    pub latency: usize,
    /// Probability that a sample is lost (the previous one is published again).
    pub dropout: f64,
}

/// The joint encoders' model (the base's six coordinates are not joints).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Counts per turn = 2^bits: positions are rounded to 2π / 2^bits (0: not quantised).
    pub bits: u32,
    /// σ of the white noise of a joint velocity from the drive (rad/s).
    pub velocity_noise: f64,
}

/// `[sim.sensors]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorsConfig {
    pub sensing: Sensing,
    /// Seed of the run's generator.
    pub seed: u64,
    pub encoders: EncoderConfig,
    /// The wrist's force sensor (the hand force).
    pub wrist: ForceSensorConfig,
    /// Each sole corner's force.
    pub soles: ForceSensorConfig,
}

impl SensorsConfig {
    /// The first invalid field, as (key under `sim.sensors`, message).
    pub fn invalid(&self) -> Option<(String, String)> {
        for (name, s) in [("wrist", &self.wrist), ("soles", &self.soles)] {
            for (key, v) in [
                ("noise", s.noise),
                ("bias", s.bias),
                ("drift", s.drift),
                ("resolution", s.resolution),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Some((format!("{name}.{key}"), format!("must be ≥ 0, got {v}")));
                }
            }
            if !(0.0..1.0).contains(&s.dropout) {
                return Some((
                    format!("{name}.dropout"),
                    format!("must be in [0, 1), got {}", s.dropout),
                ));
            }
            if s.latency > MAX_LATENCY {
                return Some((
                    format!("{name}.latency"),
                    format!("at most {MAX_LATENCY} steps, got {}", s.latency),
                ));
            }
        }
        let e = &self.encoders;
        if e.bits > 32 {
            return Some((
                "encoders.bits".into(),
                format!("at most 32, got {}", e.bits),
            ));
        }
        if !(e.velocity_noise.is_finite() && e.velocity_noise >= 0.0) {
            return Some((
                "encoders.velocity_noise".into(),
                format!("must be ≥ 0, got {}", e.velocity_noise),
            ));
        }
        None
    }
}

/// Longest latency modelled (steps).
pub const MAX_LATENCY: usize = 64;

/// Counters of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SensorCounts {
    /// Samples lost (the previous one published again), wrist and soles.
    pub wrist_dropouts: u64,
    pub sole_dropouts: u64,
}

/// One three-axis force channel: its bias, its delay line and its last published sample.
#[derive(Debug, Clone)]
struct ForceChannel {
    bias: [f64; 3],
    /// Delay line of measured samples (ring, `latency + 1` long).
    line: Vec<[f64; 3]>,
    last: [f64; 3],
    primed: bool,
}

impl ForceChannel {
    fn new(s: &ForceSensorConfig, rng: &mut ChaCha8Rng) -> Self {
        let bias = [0; 3].map(|_| {
            let u: f64 = StandardNormal.sample(rng);
            s.bias * u.signum()
        });
        Self {
            bias,
            line: vec![[0.0; 3]; s.latency + 1],
            last: [0.0; 3],
            primed: false,
        }
    }

    /// The sample published at `step` for the true force `f`: returns whether it was lost.
    fn measure(
        &mut self,
        s: &ForceSensorConfig,
        step: u64,
        dt: f64,
        rng: &mut ChaCha8Rng,
        f: &mut [f64; 3],
    ) -> bool {
        let walk = s.drift * dt.sqrt();
        for c in 0..3 {
            let (n, w): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
            self.bias[c] += walk * w;
            let mut y = f[c] + self.bias[c] + s.noise * n;
            if s.resolution > 0.0 {
                y = (y / s.resolution).round() * s.resolution;
            }
            f[c] = y;
        }
        // The delay line: write this step's sample, read the one `latency` steps old (the
        // oldest written so far while the line fills).
        let len = self.line.len() as u64;
        self.line[(step % len) as usize] = *f;
        let old = (step + 1).saturating_sub(len);
        let delayed = self.line[(old % len) as usize];
        let u: f64 = rng.random();
        let lost = self.primed && u < s.dropout;
        if !lost {
            self.last = delayed;
        }
        self.primed = true;
        *f = self.last;
        lost
    }
}

/// The sensor models of one plant run.
pub struct Sensors {
    cfg: SensorsConfig,
    rng: ChaCha8Rng,
    wrist: ForceChannel,
    soles: Vec<ForceChannel>,
    pub counts: SensorCounts,
}

impl Sensors {
    /// `None` for truth.
    pub fn new(cfg: &SensorsConfig) -> Option<Self> {
        if cfg.sensing == Sensing::Truth {
            return None;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let wrist = ForceChannel::new(&cfg.wrist, &mut rng);
        let soles = (0..N_CONTACTS)
            .map(|_| ForceChannel::new(&cfg.soles, &mut rng))
            .collect();
        Some(Self {
            cfg: *cfg,
            rng,
            wrist,
            soles,
            counts: SensorCounts::default(),
        })
    }

    /// Turns the true state in `m` into what the sensors say, at plant step `m.step` of period
    /// `dt`; `contact_points`: the sole corners (world), for the centre of pressure of the
    /// measured forces.
    pub fn apply(&mut self, m: &mut StateMsg, dt: f64, contact_points: &[[f64; 3]]) {
        let (cfg, step) = (self.cfg, m.step);
        // Joints: the configuration past the base's 7 coordinates, the velocity past its 6.
        let (nq, nv) = (m.nq as usize, m.nv as usize);
        let q_step = if cfg.encoders.bits > 0 {
            std::f64::consts::TAU / (1u64 << cfg.encoders.bits) as f64
        } else {
            0.0
        };
        if q_step > 0.0 {
            for q in m.q.iter_mut().take(nq.min(MAX_DOF)).skip(7) {
                *q = (*q / q_step).round() * q_step;
            }
        }
        for v in m.v.iter_mut().take(nv.min(MAX_DOF)).skip(6) {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            *v += cfg.encoders.velocity_noise * n;
        }
        if self
            .wrist
            .measure(&cfg.wrist, step, dt, &mut self.rng, &mut m.hand_force)
        {
            self.counts.wrist_dropouts += 1;
        }
        for (ch, f) in self.soles.iter_mut().zip(m.contact_forces.iter_mut()) {
            if ch.measure(&cfg.soles, step, dt, &mut self.rng, f) {
                self.counts.sole_dropouts += 1;
            }
        }
        // The centre of pressure of the measured forces (flat ground), as the robot computes it;
        // where they carry no weight, the previous one stays.
        let loads =
            (m.contact_forces.iter().zip(contact_points)).map(|(f, p)| (f[2], [p[0], p[1]]));
        if let (_, Some(cop), _) = super::physics::centre_of_pressure(loads) {
            m.zmp = cop;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> SensorsConfig {
        let force = ForceSensorConfig {
            noise: 0.5,
            bias: 2.0,
            drift: 0.0,
            resolution: 0.0,
            latency: 0,
            dropout: 0.0,
        };
        SensorsConfig {
            sensing: Sensing::Realistic,
            seed: 7,
            encoders: EncoderConfig {
                bits: 12,
                velocity_noise: 0.01,
            },
            wrist: force,
            soles: force,
        }
    }

    fn state(t_step: u64, hand: [f64; 3]) -> Box<StateMsg> {
        let mut m: Box<StateMsg> = Box::default();
        m.step = t_step;
        m.nq = 10;
        m.nv = 9;
        m.q[7] = 0.3;
        m.hand_force = hand;
        m
    }

    /// Statistics of the wrist over many samples: the mean is the truth plus the bias
    /// (±2 N per axis), the spread the noise's σ.
    #[test]
    fn a_force_sensor_has_its_bias_and_noise() {
        let mut s = Sensors::new(&cfg()).unwrap();
        let n = 20_000;
        let (mut sum, mut sum2) = ([0.0; 3], [0.0; 3]);
        for k in 0..n {
            let mut m = state(k, [-10.0, 0.0, 5.0]);
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            for c in 0..3 {
                sum[c] += m.hand_force[c];
                sum2[c] += m.hand_force[c] * m.hand_force[c];
            }
        }
        for (c, truth) in [-10.0, 0.0, 5.0].into_iter().enumerate() {
            let mean = sum[c] / n as f64;
            let sd = (sum2[c] / n as f64 - mean * mean).sqrt();
            assert!(
                ((mean - truth).abs() - 2.0).abs() < 0.02,
                "axis {c}: mean {mean}"
            );
            assert!((sd - 0.5).abs() < 0.02, "axis {c}: σ {sd}");
        }
    }

    /// The bias's random walk: its spread over independent runs after T seconds is drift √T.
    #[test]
    fn the_bias_drifts_as_a_random_walk() {
        let mut c = cfg();
        (c.wrist.noise, c.wrist.bias, c.wrist.drift) = (0.0, 0.0, 0.1);
        let (runs, steps, dt) = (400, 1000, 1e-3);
        let mut sum2 = 0.0;
        for seed in 0..runs {
            c.seed = seed;
            let mut s = Sensors::new(&c).unwrap();
            let mut last = 0.0;
            for k in 0..steps {
                let mut m = state(k, [0.0; 3]);
                s.apply(&mut m, dt, &[[0.0; 3]; N_CONTACTS]);
                last = m.hand_force[0];
            }
            sum2 += last * last;
        }
        let sd = (sum2 / runs as f64).sqrt();
        let expected = 0.1 * (steps as f64 * dt).sqrt();
        assert!(
            (sd / expected - 1.0).abs() < 0.15,
            "{sd} against {expected}"
        );
    }

    /// A latency of L steps publishes, at step k, the sample of step k − L; a resolution rounds.
    #[test]
    fn latency_delays_and_resolution_rounds() {
        let mut c = cfg();
        (
            c.wrist.noise,
            c.wrist.bias,
            c.wrist.latency,
            c.wrist.resolution,
        ) = (0.0, 0.0, 3, 0.25);
        let mut s = Sensors::new(&c).unwrap();
        let mut out = Vec::new();
        for k in 0..10 {
            let mut m = state(k, [k as f64 + 0.1, 0.0, 0.0]);
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            out.push(m.hand_force[0]);
        }
        assert_eq!(&out[3..], &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(
            &out[..3],
            &[0.0, 0.0, 0.0],
            "the first sample until the line fills"
        );
    }

    /// Encoders: positions on the 2π / 2^bits grid, the base untouched; velocities noisy.
    #[test]
    fn encoders_quantise_joints_only() {
        let mut s = Sensors::new(&cfg()).unwrap();
        let mut m = state(0, [0.0; 3]);
        m.q[0] = 0.123456789;
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        let step = std::f64::consts::TAU / 4096.0;
        assert_eq!(m.q[0], 0.123456789, "the base is no joint");
        assert!((m.q[7] / step - (m.q[7] / step).round()).abs() < 1e-9);
        assert!((m.q[7] - 0.3).abs() <= step / 2.0);
        assert!(m.v[6] != 0.0 && m.v[6].abs() < 0.1, "{}", m.v[6]);
    }

    /// Dropouts hold the previous sample and are counted; the same seed gives the same bytes.
    #[test]
    fn dropouts_hold_and_a_seed_reproduces() {
        let mut c = cfg();
        c.wrist.dropout = 0.2;
        let run = |c: &SensorsConfig| {
            let mut s = Sensors::new(c).unwrap();
            let mut out = Vec::new();
            for k in 0..2000 {
                let mut m = state(k, [k as f64, 0.0, 0.0]);
                s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
                out.push(m.hand_force[0].to_bits());
            }
            (out, s.counts.wrist_dropouts)
        };
        let (a, lost) = run(&c);
        assert!((300..500).contains(&lost), "{lost} of 2000 lost at p = 0.2");
        assert_eq!(a, run(&c).0);
        c.seed += 1;
        assert_ne!(a, run(&c).0);
    }

    /// The centre of pressure follows the measured forces.
    #[test]
    fn the_centre_of_pressure_is_the_measured_forces() {
        let mut c = cfg();
        (c.soles.noise, c.soles.bias) = (0.0, 0.0);
        let mut s = Sensors::new(&c).unwrap();
        let mut m = state(0, [0.0; 3]);
        let mut points = [[0.0; 3]; N_CONTACTS];
        for (k, p) in points.iter_mut().enumerate() {
            *p = [k as f64 * 0.01, 0.1, 0.0];
            m.contact_forces[k] = [0.0, 0.0, if k < 2 { 10.0 } else { 0.0 }];
        }
        s.apply(&mut m, 1e-3, &points);
        assert!((m.zmp[0] - 0.005).abs() < 1e-12 && (m.zmp[1] - 0.1).abs() < 1e-12);
    }
}
