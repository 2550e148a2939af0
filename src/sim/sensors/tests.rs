//! The sensor models through the runtime, as a plant applies them.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::*;
use crate::channels::{
    N_CONTACTS, SENSOR_HAND, SENSOR_IMU, SENSOR_JOINTS, STATE_FLAG_BASE_UNMEASURED,
};
use crate::plant::feet::fill_foot_wrenches;

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
        mocap: true,
        encoders: EncoderConfig {
            bits: 12,
            velocity_noise: 0.01,
        },
        imu: ImuConfig {
            gyro_noise_density: 2.4e-4,
            gyro_bias: 1e-3,
            gyro_bias_drift: 0.0,
            accel_noise_density: 1.7e-3,
            accel_bias: 0.02,
            accel_bias_drift: 0.0,
            tilt_error: 3.5e-3,
            orientation_noise: 0.0,
            yaw_drift: 0.0,
            latency: 0,
            dropout: 0.0,
        },
        wrist: force,
        feet: FootSensing::Corners,
        soles: force,
        foot_ft: WrenchSensorConfig {
            noise: 0.3,
            bias: 2.0,
            drift: 0.0,
            resolution: 0.0,
            moment_noise: 0.01,
            moment_bias: 0.1,
            moment_drift: 0.0,
            moment_resolution: 0.0,
            latency: 0,
            dropout: 0.0,
        },
        motor_torques: MotorTorqueConfig {
            noise: 0.0,
            friction: 0.0,
            friction_velocity: 0.05,
            viscous: 0.0,
            resolution: 0.0,
            latency: 0,
        },
    }
}

fn state(t_step: u64, hand: [f64; 3]) -> Box<StateMsg> {
    let mut m: Box<StateMsg> = Box::default();
    m.step = t_step;
    m.nq = 10;
    m.nv = 9;
    m.q[6] = 1.0;
    m.q[7] = 0.3;
    m.hand_force = hand;
    m
}

/// Statistics of the wrist over many samples: the mean is the truth plus the bias
/// (±2 N per axis), the spread the noise's σ.
#[test]
fn a_force_sensor_has_its_bias_and_noise() {
    let mut s = Sensors::new(&cfg(), 9.81, None);
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
        let mut s = Sensors::new(&c, 9.81, None);
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
    let mut s = Sensors::new(&c, 9.81, None);
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
    let mut s = Sensors::new(&cfg(), 9.81, None);
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
        let mut s = Sensors::new(c, 9.81, None);
        let mut out = Vec::new();
        for k in 0..2000 {
            let mut m = state(k, [k as f64, 0.0, 0.0]);
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            out.push(m.hand_force[0].to_bits());
        }
        (out, s.counts().get("wrist_dropouts").unwrap())
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
    let mut s = Sensors::new(&c, 9.81, None);
    let mut m = state(0, [0.0; 3]);
    let mut points = [[0.0; 3]; N_CONTACTS];
    for (k, p) in points.iter_mut().enumerate() {
        *p = [k as f64 * 0.01, 0.1, 0.0];
        m.contact_forces[k] = [0.0, 0.0, if k < 2 { 10.0 } else { 0.0 }];
    }
    s.apply(&mut m, 1e-3, &points);
    assert!((m.zmp[0] - 0.005).abs() < 1e-12 && (m.zmp[1] - 0.1).abs() < 1e-12);
}

/// The IMU of a base at rest, tilted about x: its accelerometer reads g along the world's
/// up in its own frame, plus its bias; its gyro reads its bias; its orientation is the truth
/// turned by the attitude filter's tilt error. On `truth` it reads the truth exactly.
#[test]
fn an_imu_at_rest_reads_gravity_in_its_frame() {
    let tilt = 0.3_f64;
    let at = |k: u64| {
        let mut m = state(k, [0.0; 3]);
        let r = UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0);
        m.q[3..7].copy_from_slice(&[r.i, r.j, r.k, r.w]);
        m
    };
    let up = UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0).inverse() * Vector3::z() * 9.81;
    let mut c = cfg();
    let mut exact = c;
    exact.sensing = Sensing::Truth;
    let mut s = Sensors::new(&exact, 9.81, None);
    for k in 0..3 {
        let mut m = at(k);
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        for a in 0..3 {
            assert!((m.imu_linear_acceleration[a] - up[a]).abs() < 1e-12);
            assert_eq!(m.imu_angular_velocity[a], 0.0);
        }
        assert_eq!(m.stamps, [0.0; 4]);
    }
    (c.imu.gyro_noise_density, c.imu.accel_noise_density) = (0.0, 0.0);
    let mut s = Sensors::new(&c, 9.81, None);
    let mut m = at(5);
    s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
    for a in 0..3 {
        let bias = m.imu_linear_acceleration[a] - up[a];
        assert!((bias.abs() - 0.02).abs() < 1e-12, "accel bias {bias}");
        assert!((m.imu_angular_velocity[a].abs() - 1e-3).abs() < 1e-12);
    }
    let o = m.imu_orientation;
    let meas = UnitQuaternion::from_quaternion(Quaternion::new(o[3], o[0], o[1], o[2]));
    let err = (meas * UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0).inverse()).scaled_axis();
    assert!((err.x.abs() - 3.5e-3).abs() < 1e-9 && (err.y.abs() - 3.5e-3).abs() < 1e-9);
    assert!(err.z.abs() < 1e-12, "no yaw drift configured: {err}");
}

/// A base accelerating at 2 m/s² along x: the accelerometer reads (2, 0, g) once it has two
/// states to difference.
#[test]
fn the_accelerometer_reads_the_base_acceleration() {
    let mut c = cfg();
    c.sensing = Sensing::Truth;
    let mut s = Sensors::new(&c, 9.81, None);
    let mut read = [0.0; 3];
    for k in 0..5 {
        let mut m = state(k, [0.0; 3]);
        m.v[0] = 2.0 * k as f64 * 1e-3;
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        read = m.imu_linear_acceleration;
    }
    assert!(
        (read[0] - 2.0).abs() < 1e-9 && read[1].abs() < 1e-12,
        "{read:?}"
    );
    assert!((read[2] - 9.81).abs() < 1e-12);
}

/// A foot's wrench is its corners' forces in the sole frame about their centroid: a foot
/// turned by 90° about z, loaded on its two front corners.
#[test]
fn a_foot_wrench_is_its_corners_in_the_sole_frame() {
    let mut c = cfg();
    c.sensing = Sensing::Truth;
    let mut s = Sensors::new(&c, 9.81, None);
    let mut m = state(0, [0.0; 3]);
    // Toes along +y: front-left (−x side), front-right, rear-left, rear-right; 0.2 × 0.1 m.
    let mut points = [[0.0; 3]; N_CONTACTS];
    points[..4].copy_from_slice(&[
        [-0.05, 0.1, 0.0],
        [0.05, 0.1, 0.0],
        [-0.05, -0.1, 0.0],
        [0.05, -0.1, 0.0],
    ]);
    m.contact_forces[0] = [1.0, 0.0, 50.0];
    m.contact_forces[1] = [1.0, 0.0, 50.0];
    s.apply(&mut m, 1e-3, &points);
    let w = m.foot_wrenches[0];
    // In the sole frame: x = world y, y = world −x, z = world z. The moment about the
    // centre, Σ p × f = (10, 0, −0.2) in the world: the load on the toes (CoP x = −τy / fz
    // = 0.1 m, the front edge).
    let expected = [0.0, -2.0, 100.0, 0.0, -10.0, -0.2];
    for (a, e) in w.iter().zip(expected) {
        assert!((a - e).abs() < 1e-12, "{w:?}");
    }
    assert_eq!(
        m.foot_wrenches[1], [0.0; 6],
        "a degenerate sole reads nothing"
    );
    // Sole forces not measured (a robot without foot sensors, no force plates): the foot's
    // wrench is not measured either, never a measured zero (an unloaded foot).
    m.contact_forces[2] = [f64::NAN; 3];
    s.apply(&mut m, 1e-3, &points);
    assert!(
        m.foot_wrenches[0].iter().all(|x| x.is_nan()),
        "{:?}",
        m.foot_wrenches[0]
    );
}

/// Two feet 0.2 × 0.1 m, toes along +x, 0.1 m either side of y = 0, and their corner
/// forces: the left foot on its toes (CoP x = +0.1), the right flat with a sideways pull.
fn two_feet(m: &mut StateMsg) -> [[f64; 3]; N_CONTACTS] {
    let mut points = [[0.0; 3]; N_CONTACTS];
    for (foot, y) in [(0, 0.1), (1, -0.1)] {
        let corners = [[0.1, 0.05], [0.1, -0.05], [-0.1, 0.05], [-0.1, -0.05]];
        for (i, [cx, cy]) in corners.into_iter().enumerate() {
            points[4 * foot + i] = [cx, y + cy, 0.0];
        }
    }
    for i in 0..2 {
        m.contact_forces[i] = [0.0, 0.0, 60.0];
    }
    for i in 4..8 {
        m.contact_forces[i] = [0.0, 2.0, 30.0];
    }
    points
}

/// A six-axis sensor per foot: over many samples its mean is the true wrench plus the bias
/// (±2 N, ±0.1 N m per axis), its spread the configured σ; the corners are not published;
/// without noise the CoP of its wrenches is the CoP of the true corner forces.
#[test]
fn a_six_axis_foot_sensor_measures_the_wrench() {
    let mut c = cfg();
    c.feet = FootSensing::SixAxis;
    let n = 20_000;
    let mut s = Sensors::new(&c, 9.81, None);
    let (mut sum, mut sum2) = ([0.0; 6], [0.0; 6]);
    let mut truth = [0.0; 6];
    for k in 0..n {
        let mut m = state(k, [0.0; 3]);
        let points = two_feet(&mut m);
        fill_foot_wrenches(&mut m, &points);
        truth = m.foot_wrenches[0];
        s.apply(&mut m, 1e-3, &points);
        assert!(m.contact_forces.iter().flatten().all(|f| f.is_nan()));
        for a in 0..6 {
            sum[a] += m.foot_wrenches[0][a];
            sum2[a] += m.foot_wrenches[0][a].powi(2);
        }
    }
    for a in 0..6 {
        let (bias, sigma) = if a < 3 { (2.0, 0.3) } else { (0.1, 0.01) };
        let mean = sum[a] / n as f64;
        let sd = (sum2[a] / n as f64 - mean * mean).sqrt();
        let off = (mean - truth[a]).abs();
        assert!(
            (off - bias).abs() < 0.02 * bias,
            "axis {a}: mean {mean} of {truth:?}"
        );
        assert!((sd / sigma - 1.0).abs() < 0.05, "axis {a}: σ {sd}");
    }
    // Exact sensors: the wrenches' CoP is the corners' (left 120 N at x = 0.1, y = 0.1;
    // right 120 N at x = 0, y = −0.1).
    let c = SensorsConfig {
        foot_ft: WrenchSensorConfig {
            bias: 0.0,
            noise: 0.0,
            moment_bias: 0.0,
            moment_noise: 0.0,
            ..c.foot_ft
        },
        ..c
    };
    let mut s = Sensors::new(&c, 9.81, None);
    let mut m = state(0, [0.0; 3]);
    let points = two_feet(&mut m);
    s.apply(&mut m, 1e-3, &points);
    assert!(
        (m.zmp[0] - 0.05).abs() < 1e-12 && m.zmp[1].abs() < 1e-12,
        "{:?}",
        m.zmp
    );
    assert_eq!(s.counts().get("foot_ft_dropouts"), Some(0));
}

/// An IMU in the head of the embedded robot at home, its torso pitched by 0.2 rad (neck
/// straight): at rest its accelerometer reads g tilted 0.2 rad from what one on the base
/// reads, and its orientation is 0.2 rad from the base's.
#[test]
fn a_mounted_imu_reads_its_own_frame() {
    let robot = crate::robot::Robot::embedded_default().unwrap();
    let model = &robot.model;
    let mut c = cfg();
    c.sensing = Sensing::Truth;
    let read = |mount: Option<ImuMount>| {
        let mut s = Sensors::new(&c, 9.81, mount);
        let mut m: Box<StateMsg> = Box::default();
        (m.nq, m.nv) = (model.nq as u32, model.nv as u32);
        m.q[..model.nq].copy_from_slice(robot.home.as_slice());
        let torso = model.joints[model.joint_id("torso_pitch").unwrap()].idx_q;
        m.q[torso] = 0.2;
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        let o = m.imu_orientation;
        let r = UnitQuaternion::from_quaternion(Quaternion::new(o[3], o[0], o[1], o[2]));
        (r, Vector3::from(m.imu_linear_acceleration))
    };
    let head = model.frame_id("head").unwrap();
    let (r_base, f_base) = read(None);
    let (r_head, f_head) = read(Some(ImuMount::new(model, head)));
    assert!((f_head.norm() - 9.81).abs() < 1e-9, "at rest: {f_head}");
    assert!((f_head.angle(&f_base) - 0.2).abs() < 1e-9);
    assert!((r_head.angle_to(&r_base) - 0.2).abs() < 1e-9);
    // A state that does not fit the mount's model: no sample (NaN), counted.
    let mut s = Sensors::new(&c, 9.81, Some(ImuMount::new(model, head)));
    let mut m: Box<StateMsg> = Box::default();
    (m.nq, m.nv) = (model.nq as u32 - 1, model.nv as u32);
    s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
    assert!(m.imu_orientation.iter().all(|x| x.is_nan()));
    assert_eq!(s.counts().get("imu_mount_failures"), Some(1));
}

/// A setting to spoil, the key and the message that name it.
type Invalid = (fn(&mut SensorsConfig), &'static str, &'static str);

/// A setting out of range is named by its key.
#[test]
fn an_invalid_setting_is_named() {
    assert_eq!(cfg().invalid(), None);
    let mut c = cfg();
    c.foot_ft.moment_noise = -1.0;
    assert_eq!(c.invalid().unwrap().0, "foot_ft.moment_noise");
    let mut c = cfg();
    c.imu.dropout = 1.0;
    assert_eq!(c.invalid().unwrap().0, "imu.dropout");
    let mut c = cfg();
    c.soles.latency = MAX_LATENCY + 1;
    assert_eq!(c.invalid().unwrap().0, "soles.latency");
    // Each model's own keys and messages, as the configuration's errors say them.
    let cases: [Invalid; 5] = [
        (
            |c| c.encoders.bits = 40,
            "encoders.bits",
            "at most 32, got 40",
        ),
        (
            |c| c.wrist.noise = -0.5,
            "wrist.noise",
            "must be ≥ 0, got -0.5",
        ),
        (
            |c| c.motor_torques.friction_velocity = 0.0,
            "motor_torques.friction_velocity",
            "must be > 0, got 0",
        ),
        (
            |c| c.motor_torques.latency = MAX_DELAY + 1,
            "motor_torques.latency",
            "at most 8 steps, got 9",
        ),
        (
            |c| c.imu.latency = 65,
            "imu.latency",
            "at most 64 steps, got 65",
        ),
    ];
    for (set, key, message) in cases {
        let mut c = cfg();
        set(&mut c);
        assert_eq!(c.invalid(), Some((key.into(), message.into())));
    }
}

/// A robot does not measure its base: without `mocap` the base is NaN and the flag says so;
/// stamps lag by the latency.
#[test]
fn without_mocap_the_base_is_not_published() {
    let mut c = cfg();
    (c.mocap, c.imu.latency, c.wrist.latency) = (false, 2, 1);
    let mut s = Sensors::new(&c, 9.81, None);
    let mut m = state(10, [0.0; 3]);
    m.time = 0.01;
    s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
    assert!(m.q[..7].iter().chain(&m.v[..6]).all(|x| x.is_nan()));
    assert!(m.q[7].is_finite() && m.flags & STATE_FLAG_BASE_UNMEASURED != 0);
    assert!((m.stamps[SENSOR_IMU] - 0.008).abs() < 1e-12);
    assert!((m.stamps[SENSOR_HAND] - 0.009).abs() < 1e-12);
    assert_eq!(m.stamps[SENSOR_JOINTS], 0.01);
}

/// The gyro's bias walks drift·√t whatever the rate the IMU is sampled at: every plant step or
/// every second one (a G1 on its bus), over the same 1 s the spread across seeds is the same.
#[test]
fn the_gyro_bias_walks_over_time_not_samples() {
    let spread = |every: u64| {
        let mut c = cfg();
        c.imu.gyro_noise_density = 0.0;
        c.imu.gyro_bias = 0.0;
        c.imu.gyro_bias_drift = 0.01;
        let (mut sum2, seeds) = (0.0, 400);
        for seed in 0..seeds {
            c.seed = seed;
            let mut s = Sensors::new(&c, 9.81, None);
            let mut w = 0.0;
            for k in (0..=1000).step_by(every as usize) {
                let mut m = state(k, [0.0; 3]);
                s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
                w = m.imu_angular_velocity[0];
            }
            sum2 += w * w;
        }
        (sum2 / seeds as f64).sqrt()
    };
    let (one, two) = (spread(1), spread(2));
    // 0.01 rad/s/√s over 1 s; 400 seeds: the spread's own error is about 4 %.
    for s in [one, two] {
        assert!(
            (s - 0.01).abs() < 0.0015,
            "every step {one}, every second {two}"
        );
    }
}

/// The counters, each model's by name, in the summary's keys and order (`sim.json`'s
/// `sensor_counts`): wrist, corners, six-axis feet and IMU dropouts, mounted IMU failures.
#[test]
fn the_counters_keep_their_names() {
    let mut c = cfg();
    (c.wrist.dropout, c.soles.dropout, c.imu.dropout) = (0.5, 0.5, 0.5);
    let mut s = Sensors::new(&c, 9.81, None);
    for k in 0..100 {
        s.apply(&mut state(k, [0.0; 3]), 1e-3, &[[0.0; 3]; N_CONTACTS]);
    }
    let counts = s.counts();
    let names: Vec<_> = counts.names().collect();
    assert_eq!(
        names,
        [
            "wrist_dropouts",
            "sole_dropouts",
            "foot_ft_dropouts",
            "imu_dropouts",
            "imu_mount_failures"
        ]
    );
    let json = serde_json::to_value(&counts).unwrap();
    assert_eq!(json.as_object().unwrap().len(), 5);
    // Every sample but the first may be lost; each corner is a sensor.
    for (name, samples) in [
        ("wrist_dropouts", 99),
        ("sole_dropouts", 99 * N_CONTACTS as u64),
        ("imu_dropouts", 99),
    ] {
        let n = json[name].as_u64().unwrap();
        let share = n as f64 / samples as f64;
        assert!(
            (0.35..0.65).contains(&share),
            "{name}: {n} of {samples} at p = 0.5"
        );
        assert_eq!(counts.get(name), Some(n));
    }
    assert_eq!(json["foot_ft_dropouts"], 0);
}

/// A robot's torque estimates and missing sensors in the declared list read what they read as
/// a step of their own after the applied torques (the bus plant's form): the same state, bit
/// for bit, seed for seed.
#[test]
fn the_robot_s_models_in_the_list_are_the_separate_step() {
    use crate::robot::{FootSensors, SensorSpec};
    let mut c = cfg();
    c.motor_torques = MotorTorqueConfig {
        noise: 0.01,
        friction: 0.02,
        viscous: 0.1,
        latency: 2,
        ..c.motor_torques
    };
    let spec = SensorSpec {
        feet: Some(FootSensors::None),
        wrist: false,
        joint_torques: true,
    };
    let effort = vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 30.0, 50.0, 20.0];
    let robot = RobotSensors {
        spec,
        effort: effort.clone(),
    };
    let mut listed = Sensors::with_robot(&c, 9.81, None, robot);
    let mut sensors = Sensors::new(&c, 9.81, None);
    let mut step = RobotSensing::new(spec, true, c.motor_torques, effort, c.seed);
    for k in 0..50 {
        let mut m = state(k, [1.0, 2.0, 3.0]);
        m.v[6..9].copy_from_slice(&[0.3, -0.2, 1.0]);
        let tau = [k as f64, -2.0, 0.5];
        let mut a = m.clone();
        crate::sim::process::put_applied_torques(&mut a, &tau);
        listed.apply(&mut a, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        step.take_truth(&m);
        sensors.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        crate::sim::process::put_applied_torques(&mut m, &tau);
        step.apply(&mut m);
        let bits = |m: &StateMsg| {
            let mut b: Vec<u64> = m.joint_torques.iter().map(|x| x.to_bits()).collect();
            b.extend(
                m.v.iter()
                    .chain(&m.hand_force)
                    .chain(&m.zmp)
                    .map(|x| x.to_bits()),
            );
            b
        };
        assert_eq!(bits(&a), bits(&m), "step {k}");
        assert!(a.joint_torques[6].is_finite() && a.hand_force[0].is_nan());
    }
}
