//! `upc compare` on synthetic run directories: report.md and every figure it links, SVG content,
//! PNG signature, clear errors on bad input, and the reduced-model section against
//! `ReducedLoop` run directly.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use upc::config::ControllerKind;
use upc::offline::ReducedLoop;
use upc::report::{CompareOptions, ConfigLayers, ReportError, compare};
use upc::scenario::Scenario;

const SCENARIO: &str = r#"
name = "test_impact"
description = "One 40 N test impact"
duration = 2.0
zmp_reference = [0.0, 0.0]

[force]
kind = "impacts"

[[force.impacts]]
start = 0.2
rise = 0.1
hold = 0.05
fall = 0.1
force = [-40.0, 2.0, 0.0]

[config.preview]
horizon = 60
"#;

/// Simulated duration of the synthetic runs (shorter than the scenario's, as `--duration` does).
const DURATION: f64 = 0.6;

fn fresh_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("report-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// The columns of `controller.csv` as the controller writes them (its records' own).
fn csv_header() -> Vec<&'static str> {
    let robot = upc::robot::Robot::embedded_default().expect("robot");
    let config = upc::config::Config::embedded_default().expect("config");
    let core = upc::control::ControllerCore::new(
        &robot,
        &config,
        ControllerKind::C1,
        0.001,
        [100.0, 20.0],
        [0.0, 0.0],
    )
    .expect("core");
    upc::control::server::record_columns(&core)
        .iter()
        .map(|c| c.name)
        .collect()
}

/// One controller's CSV with the logger's own header: a ZMP that moves with the impact, the
/// predicted ZMP 20 mm beyond the support's front edge for C0 only.
fn csv(controller: usize) -> String {
    let header = csv_header();
    let mut s = format!("{}\n", header.join(","));
    for k in 0..60 {
        let t = 0.01 * (k + 1) as f64;
        let bump = (-((t - 0.3) / 0.08).powi(2)).exp();
        let v: HashMap<&str, f64> = HashMap::from([
            ("t", t),
            ("com_x", -0.01 * bump),
            ("com_z", 0.52 - 0.001 * bump),
            ("zmp_meas_x", -0.05 * bump / (1 + controller) as f64),
            ("zmp_meas_y", 0.004 * bump),
            (
                "zmp_pred_x",
                if controller == 0 {
                    -0.09 * bump
                } else {
                    -0.03 * bump
                },
            ),
            ("hand_err", 0.01 * bump * (3 - controller) as f64),
            (
                "kp",
                if controller == 2 {
                    600.0 + 300.0 * bump
                } else {
                    600.0
                },
            ),
            ("f_ext_x", -40.0 * bump),
            ("f_dis_x", -38.0 * bump),
            ("hand_x", 0.2),
            ("hand_z", 0.6),
            ("sup_x_min", -0.07),
            ("sup_x_max", 0.07),
            ("sup_y_min", -0.1),
            ("sup_y_max", 0.1),
            ("wbc_solved", 1.0),
        ]);
        let row: Vec<String> = header
            .iter()
            .map(|h| format!("{:.5}", v.get(h).copied().unwrap_or(0.0)))
            .collect();
        s += &row.join(",");
        s += "\n";
    }
    s
}

/// A run directory as `upc run` writes it, with C0, C1 and C2.
fn synthetic_run(root: &Path) -> PathBuf {
    let run = root.join("synthetic");
    std::fs::create_dir_all(&run).expect("run dir");
    let scenario = root.join("test_impact.toml");
    std::fs::write(&scenario, SCENARIO).expect("scenario");
    let mut runs = Vec::new();
    for (i, c) in ["c0", "c1", "c2"].iter().enumerate() {
        std::fs::create_dir_all(run.join(c)).expect("controller dir");
        std::fs::write(run.join(c).join("controller.csv"), csv(i)).expect("csv");
        runs.push(serde_json::json!({
            "controller": c,
            "dir": run.join(c).display().to_string(),
            "wall_time": 1.0,
            "controller_summary": {
                "min_zmp_margin": 0.0123,
                "time_at_support_edge": 0.25,
                "hand_rms_error": 0.004,
                "hand_peak_error": 0.03 - 0.01 * i as f64,
                "com_height_drop": 0.001,
                "tick_p50_us": 400.0,
                "tick_p99_us": 900.0,
                "deadline_misses": 0,
                "wbc_fallbacks": 2,
                "c2_solve_mean_ms": 7.25,
                "c2_iterations_mean": 3.5
            },
            "sim_summary": null
        }));
    }
    let summary = serde_json::json!({
        "scenario": "test_impact",
        "scenario_source": scenario.display().to_string(),
        "config_files": [],
        "config_sets": [],
        "description": "One 40 N test impact",
        "duration": DURATION,
        "mode": "lockstep",
        "runs": runs,
    });
    std::fs::write(
        run.join("summary.json"),
        serde_json::to_string_pretty(&summary).expect("json"),
    )
    .expect("summary");
    run
}

fn options(out: &Path, reduced: bool) -> CompareOptions {
    CompareOptions {
        out: out.to_path_buf(),
        config: ConfigLayers::default(),
        reduced,
        png: true,
        overlay: false,
    }
}

fn font_present() -> bool {
    Path::new(upc::report::figures::DEFAULT_FONT).exists()
}

/// Every `](figures/…)` link of the report.
fn figure_links(report: &str) -> Vec<String> {
    report
        .split("](")
        .skip(1)
        .filter_map(|s| s.split(')').next())
        .filter(|l| l.starts_with("figures/"))
        .map(str::to_string)
        .collect()
}

#[test]
fn compare_writes_the_report_and_every_figure_it_links() {
    let root = fresh_dir("full");
    let run = synthetic_run(&root);
    let out = root.join("out");
    let written = compare(&[run], &options(&out, true)).expect("compare");
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");

    // Title, scenario and amplitudes, both sections.
    assert!(
        report.starts_with("# upc compare — test_impact"),
        "{report}"
    );
    assert!(report.contains("One 40 N test impact"), "{report}");
    assert!(report.contains("| 1 | 0.20 | 0.10 | 0.05 | 0.10 | -40.0 | 2.0 | 0.0 | 40.0 |"));
    assert!(report.contains("### Full simulation: metrics"));
    assert!(report.contains("### Reduced models"));
    // The summaries' figures, in the table's units; C2's solve only on C2's row.
    assert!(
        report.contains(
            "| C0 | 12.30 | 0.250 | 20.0 | 4.00 | 30.00 | 1.0 | 400 | 900 | 0 | 2 | – | – |"
        ),
        "{report}"
    );
    assert!(
        report.contains(
            "| C2 | 12.30 | 0.250 | 0.0 | 4.00 | 10.00 | 1.0 | 400 | 900 | 0 | 2 | 7.25 | 3.5 |"
        ),
        "{report}"
    );

    let links = figure_links(&report);
    for name in ["zmp", "hand_error", "com", "kp", "force"] {
        for section in ["synthetic", "synthetic_reduced"] {
            let svg = format!("figures/{section}_{name}.svg");
            assert!(links.contains(&svg), "{svg} not linked: {links:?}");
        }
    }
    for link in &links {
        let path = out.join(link);
        let bytes = std::fs::read(&path).unwrap_or_default();
        assert!(!bytes.is_empty(), "{} is missing or empty", path.display());
        if link.ends_with(".svg") {
            let text = String::from_utf8(bytes).expect("SVG is UTF-8");
            assert!(text.trim_start().starts_with("<svg") && text.trim_end().ends_with("</svg>"));
            assert_eq!(
                text.matches("<text").count(),
                text.matches("</text>").count()
            );
            for label in ["C0", "C1", "C2"] {
                assert!(text.contains(label), "{link} lacks the series {label}");
            }
        }
    }
    let zmp = std::fs::read_to_string(out.join("figures/synthetic_zmp.svg")).expect("zmp");
    assert!(zmp.contains("support") && zmp.contains("reference"));

    let pngs: Vec<&PathBuf> = written
        .figures
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    assert_eq!(written.png, font_present());
    if font_present() {
        assert!(pngs.len() >= 10, "{pngs:?}");
        for p in pngs {
            let bytes = std::fs::read(p).expect("png");
            assert!(
                bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
                "{} is not a PNG",
                p.display()
            );
            assert!(links.contains(&format!(
                "figures/{}",
                p.file_name().unwrap().to_string_lossy()
            )));
        }
    } else {
        assert!(pngs.is_empty());
    }
}

#[test]
fn a_missing_csv_is_an_error_naming_the_path() {
    let root = fresh_dir("missing");
    let run = synthetic_run(&root);
    let csv = run.join("c1").join("controller.csv");
    std::fs::remove_file(&csv).expect("remove");
    let err = compare(&[run], &options(&root.join("out"), false)).expect_err("must fail");
    assert!(matches!(err, ReportError::Io { .. }), "{err:?}");
    assert!(
        err.to_string().contains(&csv.display().to_string()),
        "{err}"
    );
    // Nothing half-written.
    assert!(!root.join("out").join("report.md").exists());
}

#[test]
fn a_corrupt_csv_is_an_error_naming_the_path_and_line() {
    let root = fresh_dir("corrupt");
    let run = synthetic_run(&root);
    let csv = run.join("c2").join("controller.csv");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // Line 4 keeps its field count; its third value (com_y) is not a number.
    let mut fields: Vec<String> = lines[3].split(',').map(str::to_string).collect();
    fields[2] = "abc".into();
    lines[3] = fields.join(",");
    std::fs::write(&csv, lines.join("\n")).expect("write");
    let err = compare(
        std::slice::from_ref(&run),
        &options(&root.join("out"), false),
    )
    .expect_err("must fail");
    let msg = err.to_string();
    assert!(msg.contains(&csv.display().to_string()), "{msg}");
    assert!(
        msg.contains("line 4") && msg.contains("`abc`") && msg.contains("com_y"),
        "{msg}"
    );

    // A CSV without the measured ZMP is refused by name, too.
    std::fs::write(&csv, "t,hand_err\n0.01,0.0\n").expect("write");
    let msg = compare(
        std::slice::from_ref(&run),
        &options(&root.join("out"), false),
    )
    .expect_err("must fail")
    .to_string();
    assert!(
        msg.contains("zmp_meas_x") && msg.contains(&csv.display().to_string()),
        "{msg}"
    );

    // And a corrupt summary.
    std::fs::write(run.join("summary.json"), "{ not json").expect("write");
    let msg = compare(
        std::slice::from_ref(&run),
        &options(&root.join("out"), false),
    )
    .expect_err("must fail")
    .to_string();
    assert!(
        msg.contains("summary.json") && msg.contains("JSON"),
        "{msg}"
    );
}

#[test]
fn the_reduced_section_holds_the_metrics_of_reduced_loop() {
    let root = fresh_dir("reduced");
    let run = synthetic_run(&root);
    let out = root.join("out");
    compare(&[run], &options(&out, true)).expect("compare");
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");

    // The same scenario, cut to the run's duration, and its config layers, built here.
    let mut scenario =
        Scenario::load(&root.join("test_impact.toml").display().to_string()).expect("scenario");
    scenario.duration = DURATION;
    let mut layers = upc::config::Config::default_layers().expect("defaults");
    layers.push_table("scenario", scenario.config.clone().expect("[config]"));
    let config = layers.build().expect("config");
    assert_eq!(config.preview.horizon, 60);
    let robot = upc::robot::Robot::embedded_default()
        .expect("robot")
        .reduced();
    for kind in [ControllerKind::C0, ControllerKind::C1, ControllerKind::C2] {
        let r = ReducedLoop::new(&config, robot, &scenario, kind)
            .run()
            .expect("reduced loop");
        assert_eq!(r.rows.len(), 120);
        let m = &r.metrics;
        let margin = r
            .rows
            .iter()
            .map(|row| {
                let [x, y] = row.zmp;
                (x + 0.07).min(0.07 - x).min(y + 0.10).min(0.10 - y)
            })
            .fold(f64::INFINITY, f64::min);
        let expected = format!(
            "| {} | {:.2} | {:.2} | {:.3} | {:.2} | {:.2} | {:.2} |",
            kind.name().to_uppercase(),
            m.max_zmp_error * 1e3,
            margin * 1e3,
            m.time_outside_support,
            m.max_support_excursion * 1e3,
            m.hand_rms_error * 1e3,
            m.hand_peak_error * 1e3,
        );
        assert!(
            report.contains(&expected),
            "reduced section lacks {expected}\n{report}"
        );
    }
}

#[test]
fn without_the_font_compare_writes_svgs_only_with_one_warning() {
    let root = fresh_dir("nofont");
    let run = synthetic_run(&root);
    let out = root.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_upc"))
        .arg("compare")
        .arg(&run)
        .arg("--out")
        .arg(&out)
        .arg("--no-reduced")
        .env("UPC_REPORT_FONT", root.join("no-such-font.ttf"))
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert_eq!(stderr.matches("no PNG").count(), 1, "{stderr}");
    assert!(stderr.contains("no-such-font.ttf"), "{stderr}");
    let figures: Vec<String> = std::fs::read_dir(out.join("figures"))
        .expect("figures/")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert!(figures.iter().any(|f| f.ends_with(".svg")), "{figures:?}");
    assert!(!figures.iter().any(|f| f.ends_with(".png")), "{figures:?}");
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(!report.contains("### Reduced models"));
    for link in figure_links(&report) {
        assert!(out.join(&link).exists(), "{link}");
    }

    // A missing run directory is an error naming it, through the command line.
    let o = Command::new(env!("CARGO_BIN_EXE_upc"))
        .arg("compare")
        .arg(root.join("nowhere"))
        .output()
        .expect("runs");
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("nowhere") && stderr.contains("summary.json"),
        "{stderr}"
    );
}
