//! The forecast corrected by the measured hand force, in closed loop on the full simulation
//! (docs/forecast_correction.md): a forecast 1.5 times too strong no longer topples C1, a
//! phantom push of twice C1's capability leaves the robot standing (the capture-point guard),
//! an exact forecast gives C1's figures, and without any forecaster C1 stands a push of 1.5
//! times C0's capability that topples C0. Each case is one lockstep `upc run` of a single 1 s
//! raised-cosine impact along x (`upc capability`'s), with the correction on (the default) and
//! off.

mod support;

use serde_json::Value;
use support::procs::*;
use upc::capability::{Direction, impact_toml};

/// C1's capability with the forecast as received on this impact (N, the bisection;
/// docs/results/robustness.md): the phantom claim is up to twice this.
const C1_CAPABILITY: f64 = 75.0;
/// Below this every amplitude stands for C1 as received (N, the monotone capability; the
/// bisection's 75 N is a pocket above falls at 60–70 N; docs/results/robustness.md).
const C1_MONOTONE_CAPABILITY: f64 = 55.0;
/// C0's (N; docs/results/capability.md).
const C0_CAPABILITY: f64 = 30.0;

struct Case<'a> {
    controller: &'a str,
    amplitude: f64,
    /// The impact's duration (s).
    duration: f64,
    /// The forecast is `scale` × the force, `shift` s late.
    scale: f64,
    shift: f64,
    phantom: bool,
    correction: bool,
    extra: &'a [&'a str],
}

/// The controller summary of one `upc run` of the case.
fn run(s: &Scratch, name: &str, c: &Case) -> Value {
    let scenario = s.path(&format!("{name}.toml"));
    std::fs::write(
        &scenario,
        impact_toml(c.amplitude, c.duration, Direction::X),
    )
    .expect("scenario");
    let mut args: Vec<String> = [
        "run",
        "--quiet",
        "--controller",
        c.controller,
        "--name",
        name,
        "--out",
        s.dir.to_str().expect("utf-8"),
        "--forecast-error-scale",
        &c.scale.to_string(),
        "--forecast-error-shift",
        &c.shift.to_string(),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    args.push("--scenario".into());
    args.push(scenario.display().to_string());
    if c.phantom {
        args.extend(["--sim-set".into(), "sim.push=\"none\"".into()]);
    }
    if !c.correction {
        // As received: neither corrected nor taken along the door's path (FC-0).
        args.extend([
            "--set".into(),
            "controller.forecast_correction.enabled=false".into(),
            "--set".into(),
            "controller.forecast_on_free_direction=false".into(),
        ]);
    }
    args.extend(c.extra.iter().map(|a| a.to_string()));
    upc_ok(&args);
    json(&s.path(&format!("{name}/{}/controller.json", c.controller)))
}

/// Pearson's correlation of the two columns of `xy`.
fn correlation(xy: &[[f64; 2]]) -> f64 {
    let n = xy.len() as f64;
    let mean = |k: usize| xy.iter().map(|p| p[k]).sum::<f64>() / n;
    let (mx, my) = (mean(0), mean(1));
    let cov = |a: usize, ma: f64, b: usize, mb: f64| {
        xy.iter().map(|p| (p[a] - ma) * (p[b] - mb)).sum::<f64>()
    };
    cov(0, mx, 1, my) / (cov(0, mx, 0, mx) * cov(1, my, 1, my)).sqrt()
}

fn fell(j: &Value) -> bool {
    f(j, "com_height_drop") > 0.05 || f(j, "time_at_support_edge") > 0.25
}

#[test]
fn a_forecast_too_strong_by_half_no_longer_topples_c1() {
    let _one = serial();
    let s = Scratch::new("fc_scale");
    let case = |correction| Case {
        controller: "c1",
        amplitude: 52.0,
        duration: 1.0,
        scale: 1.5,
        shift: 0.0,
        phantom: false,
        correction,
        extra: &[],
    };
    let raw = run(&s, "raw", &case(false));
    let corrected = run(&s, "corrected", &case(true));
    eprintln!(
        "× 1.5 at 52 N: raw drop {:.1} mm, edge {:.2} s; corrected drop {:.1} mm, edge {:.2} s, {:?}",
        f(&raw, "com_height_drop") * 1e3,
        f(&raw, "time_at_support_edge"),
        f(&corrected, "com_height_drop") * 1e3,
        f(&corrected, "time_at_support_edge"),
        corrected["forecast_correction"]
    );
    assert!(
        fell(&raw),
        "the uncorrected forecast should topple C1: {raw}"
    );
    assert!(!fell(&corrected), "{corrected}");
    // A wrist sensor measures the hand force: `"auto"` feeds it back as measured.
    assert_eq!(u(&corrected, "hand_force_modelled_ticks"), 0, "{corrected}");
    // The forecast is 1.5 × the force: κ̂ ≈ 1/1.5 while the push is measured (its middle,
    // 1.2–1.8 s), read from the controller's CSV.
    let text = std::fs::read_to_string(s.path("corrected/c1/controller.csv")).expect("csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (t, k) = (col("t"), col("corr_factor"));
    let factors: Vec<f64> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| (1.2..=1.8).contains(&c[t].parse::<f64>().unwrap_or(0.0)))
        .map(|c| c[k].parse().expect("factor"))
        .collect();
    assert!(!factors.is_empty());
    for k in &factors {
        assert!((k - 1.0 / 1.5).abs() < 0.15, "κ̂ {k}");
    }
}

#[test]
fn a_phantom_push_beyond_c1_s_capability_leaves_the_robot_standing() {
    let _one = serial();
    let s = Scratch::new("fc_phantom");
    let amplitude = 2.0 * C1_CAPABILITY;
    let case = |correction| Case {
        controller: "c1",
        amplitude,
        duration: 1.0,
        scale: 1.0,
        shift: 0.0,
        phantom: true,
        correction,
        extra: &[],
    };
    let raw = run(&s, "raw", &case(false));
    let corrected = run(&s, "corrected", &case(true));
    eprintln!(
        "phantom {amplitude} N: raw drop {:.1} mm; corrected drop {:.2} mm, margin {:.1} mm, {:?}",
        f(&raw, "com_height_drop") * 1e3,
        f(&corrected, "com_height_drop") * 1e3,
        f(&corrected, "min_zmp_margin") * 1e3,
        corrected["forecast_correction"]
    );
    assert!(
        fell(&raw),
        "the phantom should topple uncorrected C1: {raw}"
    );
    assert!(f(&corrected, "com_height_drop") < 0.005, "{corrected}");
    assert!(!fell(&corrected), "{corrected}");
    assert_eq!(u(&corrected, "wbc_fallbacks"), 0, "{corrected}");
    let c = &corrected["forecast_correction"];
    assert!(u(c, "contradictions") >= 1, "{c}");
    assert!(f(c, "factor_min") < 0.2, "{c}");
}

/// An exact forecast is not refused and C1 does at least as well with the correction: the
/// measured force lags the door's hinge force by about 30 ms (the door's and the arm's own
/// dynamics), which the correction follows, so its margin is larger, not equal.
#[test]
fn an_exact_forecast_keeps_c1_s_figures() {
    let _one = serial();
    let s = Scratch::new("fc_exact");
    let case = |correction| Case {
        controller: "c1",
        amplitude: 0.9 * C1_MONOTONE_CAPABILITY,
        duration: 1.0,
        scale: 1.0,
        shift: 0.0,
        phantom: false,
        correction,
        extra: &[],
    };
    let raw = run(&s, "raw", &case(false));
    let corrected = run(&s, "corrected", &case(true));
    for k in ["min_zmp_margin", "com_height_drop", "hand_rms_error"] {
        eprintln!(
            "{k}: raw {:.5}, corrected {:.5}",
            f(&raw, k),
            f(&corrected, k)
        );
    }
    assert!(
        f(&corrected, "min_zmp_margin") >= f(&raw, "min_zmp_margin") - 2e-3,
        "raw {raw}, corrected {corrected}"
    );
    assert!(f(&corrected, "com_height_drop") <= f(&raw, "com_height_drop") + 1e-3);
    assert!(f(&corrected, "hand_rms_error") <= f(&raw, "hand_rms_error") + 2e-3);
    assert!(!fell(&corrected), "{corrected}");
    let c = &corrected["forecast_correction"];
    assert_eq!(u(c, "contradictions"), 0, "{c}");
}

/// No forecaster, on a push C0 cannot take (1.5 × its capability; C0 falls there, as the next
/// test shows): the force C1 previews at each tick is the measured hand force, and the run is
/// reproducible.
#[test]
fn without_a_forecaster_the_measured_force_is_previewed() {
    let _one = serial();
    let s = Scratch::new("fc_none");
    let amplitude = 1.5 * C0_CAPABILITY;
    let case = Case {
        controller: "c1",
        amplitude,
        duration: 1.0,
        scale: 1.0,
        shift: 0.0,
        phantom: false,
        correction: true,
        extra: &["--no-forecaster"],
    };
    let a = run(&s, "a", &case);
    assert!(
        a["forecast_never_received"].as_bool().unwrap_or(false),
        "{a}"
    );
    assert_eq!(a["forecast_lost"], false, "{a}");
    assert!(a["reproducible"].as_bool().unwrap_or(false), "{a}");
    // The previewed force (`f_ext`, the first preview step's) is the measured one (`f_meas`)
    // extrapolated along its shrunk trend (FC-3b, docs/forecast_correction.md): it leads the
    // measurement on the rise and rounds the peak off, so through the push it stays within a
    // fifth of the peak at worst, 15 % RMS, and follows its shape (correlation above 0.95).
    // Previewing nothing, or half the force, breaks each bound.
    let text = std::fs::read_to_string(s.path("a/c1/controller.csv")).expect("csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (t, ext, meas) = (col("t"), col("f_ext_x"), col("f_meas_x"));
    let rows: Vec<[f64; 3]> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .map(|c| [t, ext, meas].map(|i| c[i].parse::<f64>().expect("number")))
        .collect();
    let peak = rows.iter().map(|r| r[2].abs()).fold(0.0, f64::max);
    assert!(peak > 0.5 * amplitude, "measured peak {peak} N");
    let worst = rows.iter().map(|r| (r[1] - r[2]).abs()).fold(0.0, f64::max);
    let push: Vec<f64> = rows
        .iter()
        .filter(|r| r[2].abs() > 0.1 * peak)
        .map(|r| r[1] - r[2])
        .collect();
    let rms = (push.iter().map(|e| e * e).sum::<f64>() / push.len() as f64).sqrt();
    eprintln!(
        "{amplitude} N: measured peak {peak:.1} N, previewed − measured ≤ {worst:.2} N, RMS \
         {rms:.2} N over {} ticks",
        push.len()
    );
    let corr = correlation(&rows.iter().map(|r| [r[1], r[2]]).collect::<Vec<_>>());
    eprintln!("correlation {corr:.4}");
    assert!(push.len() > 50, "{} ticks of push", push.len());
    assert!(worst < 0.2 * peak, "previewed − measured up to {worst} N");
    assert!(rms < 0.15 * peak, "previewed − measured RMS {rms} N");
    assert!(corr > 0.95, "correlation {corr}");
    assert!(!fell(&a), "{a}");
    let b = run(&s, "b", &case);
    assert_eq!(a["ticks"], b["ticks"], "{b}");
    assert_eq!(
        csv_without(
            &s.path("a/c1/controller.csv"),
            &["tick_us", "wbc_us", "c2_solve_ms"]
        ),
        csv_without(
            &s.path("b/c1/controller.csv"),
            &["tick_us", "wbc_us", "c2_solve_ms"]
        )
    );
}

/// A robot with only a wrist force sensor (no forecaster): the measured force, held and
/// extrapolated along its trend, lets C1 stand 1.5 times the push that C0 stands.
#[test]
fn without_a_forecaster_c1_stands_half_again_c0_s_capability() {
    let _one = serial();
    let s = Scratch::new("fc_measured_only");
    let case = |controller| Case {
        controller,
        amplitude: 1.5 * C0_CAPABILITY,
        duration: 1.0,
        scale: 1.0,
        shift: 0.0,
        phantom: false,
        correction: true,
        extra: &["--no-forecaster"],
    };
    let c0 = run(&s, "c0", &case("c0"));
    let c1 = run(&s, "c1", &case("c1"));
    eprintln!(
        "{} N, no forecaster: C0 drop {:.1} mm, edge {:.2} s; C1 drop {:.1} mm, edge {:.2} s",
        1.5 * C0_CAPABILITY,
        f(&c0, "com_height_drop") * 1e3,
        f(&c0, "time_at_support_edge"),
        f(&c1, "com_height_drop") * 1e3,
        f(&c1, "time_at_support_edge")
    );
    assert!(fell(&c0), "{c0}");
    assert!(!fell(&c1), "{c1}");
    assert_eq!(u(&c1, "wbc_fallbacks"), 0, "{c1}");
}

/// Forecasts of the wrong shape on a push C0 cannot take (4/3 × its capability) that C1 stands
/// without a forecaster: C1 stands with every one of them. Before the forecast was weighed by
/// its record (FC-5) and its amplification bounded (FC-4b), the forecast stretched ×2 toppled
/// C1 on such a push (45 N: CoM drop 485 mm) and the truncated and decaying ones kept it on the
/// support edge for more than 0.25 s (docs/results/robustness.md). The wrong shapes whose
/// record shows it (the push ending a second late) are discounted; the exact forecast never is.
/// A forecast that ends half-way is exact until then: at 1.5 × C0's capability it needs the
/// guard on its easing (VG-3, `ease_margin`); with the guard off it kept C1 on the heel edge for
/// 0.27 s at 44 N.
#[test]
fn a_forecast_of_the_wrong_shape_leaves_c1_standing() {
    let _one = serial();
    let s = Scratch::new("fc_shapes");
    for (shape, amplitude) in [
        ("exact", 40.0),
        ("truncated:0.5", 40.0),
        ("decaying:0.3", 40.0),
        ("step", 40.0),
        ("stretched:2", 40.0),
        ("rotated:30", 40.0),
        ("stretched:2", 1.5 * C0_CAPABILITY),
        ("truncated:0.5", 1.5 * C0_CAPABILITY),
    ] {
        let args = ["--forecast-error-shape", shape];
        let case = Case {
            controller: "c1",
            amplitude,
            duration: 1.0,
            scale: 1.0,
            shift: 0.0,
            phantom: false,
            correction: true,
            extra: &args,
        };
        let name = format!("{}_{amplitude}", shape.replace([':', '.'], "_"));
        let j = run(&s, &name, &case);
        let fc = &j["forecast_correction"];
        eprintln!(
            "{amplitude} N, {shape}: drop {:.1} mm, edge {:.2} s, weight ≥ {:.2}, {} discounts",
            f(&j, "com_height_drop") * 1e3,
            f(&j, "time_at_support_edge"),
            f(fc, "weight_min"),
            u(fc, "discounts")
        );
        assert!(!fell(&j), "{shape} at {amplitude} N: {j}");
        match shape {
            "exact" => assert_eq!(u(fc, "discounts"), 0, "{fc}"),
            "stretched:2" => assert!(u(fc, "discounts") >= 1, "{shape}: {fc}"),
            _ => {}
        }
    }
}

/// A late, weak forecast of a short impact (half the force, 150 ms late; 0.3 s, 94 N): the
/// correction finds it within 50 ms of the onset (κ̂ ≈ 2, τ̂ ≈ −150 ms), but FC-5's record still
/// holds the predictions made before it did, and its hedge toward the measurement (w ≈ 0.75 at
/// the peak) previewed a quarter of the peak push past the push's end: 0.315 s on the heel edge,
/// a fall by `upc capability`'s criteria. The capture point under the measured push is then
/// beyond the heel, where holding the push cannot save the robot and only its easing can
/// (FC-5b): the forecast's easing is kept from the hedge and C1 stands. Read back from the
/// CSV: ticks where the easing was believed in full, the forecast discounted and the capture
/// point beyond the heel edge.
#[test]
fn a_late_weak_forecast_of_a_short_impact_keeps_its_easing_beyond_the_edge() {
    let _one = serial();
    let s = Scratch::new("fc_late_weak");
    let case = Case {
        controller: "c1",
        amplitude: 94.0,
        duration: 0.3,
        scale: 0.5,
        shift: 0.15,
        phantom: false,
        correction: true,
        extra: &[],
    };
    let j = run(&s, "late_weak", &case);
    let (fc, guard) = (&j["forecast_correction"], &j["viability"]);
    eprintln!(
        "94 N, 0.3 s, κ 0.5, τ +150 ms: drop {:.1} mm, edge {:.3} s, weight ≥ {:.2}, easing believed {:.3} s",
        f(&j, "com_height_drop") * 1e3,
        f(&j, "time_at_support_edge"),
        f(fc, "weight_min"),
        f(guard, "easing_believed_time")
    );
    assert!(!fell(&j), "{j}");
    assert!(f(guard, "easing_believed_time") > 0.0, "{guard}");
    let text = std::fs::read_to_string(s.path("late_weak/c1/controller.csv")).expect("csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (believed, w, capture, heel) = (
        col("guard_easing_x"),
        col("corr_weight"),
        col("capture_x"),
        col("sup_x_min"),
    );
    let kept = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>().unwrap_or(f64::NAN))
                .collect::<Vec<_>>()
        })
        .filter(|c| c[believed] == 1.0 && c[w] < 0.9 && c[capture] < c[heel])
        .count();
    assert!(
        kept > 0,
        "no tick kept the easing from a hedge beyond the heel"
    );
}

/// `upc robustness` end to end on a one-cell grid: the table, the CSV and the heat map, with
/// the monotone check.
#[test]
fn the_robustness_sweep_writes_its_map() {
    let _one = serial();
    let s = Scratch::new("fc_sweep");
    let out = s.dir.join("sweep");
    // A config layer that changes nothing, until its text changes below.
    let layer = s.path("layer.toml");
    std::fs::write(&layer, "# a lab's layer\n").expect("layer");
    let args = [
        "robustness",
        "--config",
        layer.to_str().expect("utf-8"),
        "--controllers",
        "c0,c1",
        "--durations",
        "1.0",
        "--scales",
        "1",
        "--shifts",
        "0",
        "--no-phantom",
        "--shapes",
        "rotated:30",
        "--max",
        "1.0=80",
        "--tol",
        "20",
        "--monotone",
        "20",
        "--quiet",
        "--out",
    ];
    upc_ok(args.iter().copied().chain([out.to_str().expect("utf-8")]));
    let j = json(&out.join("robustness.json"));
    let rows = j["rows"].as_array().expect("rows");
    let survived = |c: &str| {
        rows.iter()
            .find(|r| r["controller"] == c && r["shape"] == "exact")
            .and_then(|r| r["survived"].as_f64())
            .unwrap_or_else(|| panic!("no {c} in {j}"))
    };
    // C1 (exact forecast, 55 N monotone) beats C0 (30 N) by at least the bisection's 20 N
    // resolution: C0 falls at 40 N, C1 stands it.
    eprintln!("C0 {} N, C1 {} N", survived("C0"), survived("C1"));
    assert!(survived("C0") < 40.0, "{j}");
    assert!(survived("C1") >= 40.0, "{j}");
    assert!(survived("C1") >= survived("C0") + 20.0, "{j}");
    // `--monotone 20`: each cell's grid ran below its bisection (the bisection's case at
    // least, plus one per 20 N below its result), and never reads above it (the shape cell too).
    for r in rows {
        let num = |k: &str| r[k].as_f64().unwrap_or_else(|| panic!("no {k} in {r}"));
        let (survived, monotone) = (num("survived"), num("monotone"));
        assert!(monotone <= survived && monotone >= 20.0, "{r}");
        assert!(num("runs") >= (survived / 20.0).ceil(), "{r}");
    }
    let csv = std::fs::read_to_string(out.join("robustness.csv")).expect("csv");
    assert!(
        csv.lines().next().unwrap_or("").ends_with(",monotone"),
        "{csv}"
    );
    // The shape cell (`--shapes`): its own row, off the κ × τ map, in a table of its own.
    let rotated: Vec<&Value> = rows.iter().filter(|r| r["shape"] == "rotated:30").collect();
    assert_eq!(rotated.len(), 1, "{j}");
    assert_eq!(rotated[0]["controller"], "C1", "{j}");
    assert!(
        rotated[0]["survived"].as_f64().is_some_and(|s| s > 0.0),
        "{j}"
    );
    let md = std::fs::read_to_string(out.join("robustness.md")).expect("md");
    assert!(md.contains("| κ \\ τ (ms) |"), "{md}");
    assert!(md.contains("| `rotated:30` |"), "{md}");
    assert!(out.join("figures/robustness_c1_1000ms.svg").exists());
    // The shape cells' heat map: a row per forecast, a column per forecasting controller, the
    // promise (95 % of no forecast) as the outline's floor.
    let shapes = std::fs::read_to_string(out.join("figures/robustness_shapes_1000ms.svg"))
        .expect("the shape heat map");
    assert!(
        shapes.contains(">rotated:30<") && shapes.contains(">C1<"),
        "{shapes}"
    );
    assert!(md.contains("figures/robustness_shapes_1000ms.svg"), "{md}");
    // Each cell was saved as it ended: the same sweep again runs none and writes the same map.
    let again = std::process::Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(args)
        .arg(&out)
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc starts");
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{err}");
    assert!(err.contains("3 of 3 cells already done"), "{err}");
    assert_eq!(
        std::fs::read_to_string(out.join("robustness.csv")).expect("csv"),
        csv
    );
    // A saved cell stands for the build and the files its command line names: the config
    // file's text changed (a comment only), the same cell (C0's, the quickest) runs again, to
    // the same row.
    std::fs::write(&layer, "# a lab's layer, edited\n").expect("layer");
    let c0_only: Vec<&str> = args
        .iter()
        .map(|&a| if a == "c0,c1" { "c0" } else { a })
        .filter(|&a| a != "--shapes" && a != "rotated:30")
        .collect();
    let edited = std::process::Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(&c0_only)
        .arg(&out)
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc starts");
    let err = String::from_utf8_lossy(&edited.stderr);
    assert!(edited.status.success(), "{err}");
    assert!(!err.contains("already done"), "{err}");
    let c0_row = |csv: &str| -> String {
        let row = csv.lines().find(|l| l.starts_with("C0,"));
        row.unwrap_or_else(|| panic!("no C0 row in {csv}"))
            .to_string()
    };
    let again = std::fs::read_to_string(out.join("robustness.csv")).expect("csv");
    assert_eq!(again.lines().count(), 2, "{again}");
    assert_eq!(c0_row(&again), c0_row(&csv));
}

/// A case the plant refuses to play (MuJoCo cannot play a phantom: it pushes through the door)
/// never runs; its controller's summary of zeros must not read as a robot that stood. Its cell
/// fails with the plant's reason and the sweep ends in an error; `--plant mujoco` alone skips
/// the phantoms.
#[test]
fn a_case_the_plant_refuses_fails_its_cell_instead_of_counting_as_survived() {
    let _one = serial();
    let s = Scratch::new("fc_refused");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_upc"))
        .args([
            "robustness",
            "--plant",
            "mujoco",
            "--controllers",
            "c1",
            "--durations",
            "1.0",
            "--scales",
            "1",
            "--shifts",
            "0",
            "--tol",
            "50",
            "--quiet",
            "--sim-set",
            "sim.push=\"none\"",
            "--out",
        ])
        .arg(s.dir.join("sweep"))
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc starts");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("the case never ran"), "{err}");
    assert!(err.contains("no phantoms on the MuJoCo plant"), "{err}");
    assert!(err.contains("sim.push must be"), "{err}");
}
