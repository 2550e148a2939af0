//! The controller's seam for parts (`upc::control::part`, docs/architecture.md): a part is
//! run at its stage, reset with the core, and its columns and summary entries come with it; the
//! parts' settings are checked at load, their defaults read from `config/default.toml`.

mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use support::humanoid::rig;
use upc::col;
use upc::config::{Config, ControllerKind};
use upc::control::parts::PIPELINE;
use upc::control::{ControllerPart, Stage, TickError, TickFrame, TickInputs};
use upc::record::Record;

/// A part that adds a constant force on the CoM (as an observer would) and counts its calls.
struct ConstantPush {
    force: f64,
    updates: Arc<AtomicU64>,
    resets: Arc<AtomicU64>,
}

impl ControllerPart for ConstantPush {
    fn name(&self) -> &'static str {
        "constant_push"
    }
    fn stages(&self) -> &'static [Stage] {
        &[Stage::Disturbance]
    }
    fn reset(&mut self) {
        self.resets.fetch_add(1, Ordering::Relaxed);
    }
    fn update(&mut self, _: Stage, _: &TickInputs, frame: &mut TickFrame) -> Result<(), TickError> {
        self.updates.fetch_add(1, Ordering::Relaxed);
        frame.com_forces.add([self.force, 0.0], 1.0)
    }
    fn record(&self, out: &mut Record) {
        out.put(col!(fixed("push_x", 2).plot("push/x")), self.force);
    }
    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        out.insert(
            "constant_push".into(),
            serde_json::json!({ "updates": self.updates.load(Ordering::Relaxed) }),
        );
    }
}

/// A part added to the core runs every tick at its stage, changes what the preview does (a
/// CoM force it must lean against), records its column after the pipeline's and reports its
/// summary; a reset reaches it.
#[test]
fn an_added_part_runs_records_reports_and_resets_with_the_core() {
    let config = Config::embedded_default().expect("defaults");
    let (updates, resets) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let mut plain = rig(&config, ControllerKind::C0);
    let mut pushed = rig(&config, ControllerKind::C0);
    pushed.core.add_part(Box::new(ConstantPush {
        force: -60.0,
        updates: updates.clone(),
        resets: resets.clone(),
    }));
    assert_eq!(plain.tick_frozen(0..20), 0);
    assert_eq!(pushed.tick_frozen(0..20), 0);
    assert_eq!(updates.load(Ordering::Relaxed), 20);
    // A push along −x is leant against: the CoM is commanded toward +x, more than without it.
    let (a0, a1) = (
        plain.core.last.com_acc_cmd[0],
        pushed.core.last.com_acc_cmd[0],
    );
    assert!(a1 > a0 + 1e-3, "without {a0}, with the push {a1}");

    let mut with = Record::default();
    pushed.core.record(&mut with);
    let mut without = Record::default();
    plain.core.record(&mut without);
    let names = |r: &Record| r.columns().iter().map(|c| c.name).collect::<Vec<_>>();
    let (mut expected, got) = (names(&without), names(&with));
    expected.push("push_x");
    assert_eq!(
        got, expected,
        "the part's column comes after the pipeline's"
    );
    assert_eq!(with.get("push_x"), Some(-60.0));

    let mut summary = serde_json::Map::new();
    pushed.core.summarize(&mut summary);
    assert_eq!(summary["constant_push"]["updates"], 20);
    pushed.core.reset();
    assert_eq!(resets.load(Ordering::Relaxed), 1);
}

/// A part that estimates the centre of pressure (as a lab's own observer would).
struct CopGuess(&'static str);

impl ControllerPart for CopGuess {
    fn name(&self) -> &'static str {
        self.0
    }
    fn stages(&self) -> &'static [Stage] {
        &[Stage::Disturbance]
    }
    fn reset(&mut self) {}
    fn update(&mut self, s: Stage, _: &TickInputs, frame: &mut TickFrame) -> Result<(), TickError> {
        *frame.cop.write(self.0, s)? = [0.0, 0.0];
        Ok(())
    }
    fn record(&self, _: &mut Record) {}
    fn summarize(&self, _: &mut serde_json::Map<String, serde_json::Value>) {}
}

/// The frame's slots combine as they say: two parts' forces on the CoM add up to one part's
/// of their sum, and a second part estimating a quantity another estimated at the same stage
/// is refused, the error naming both.
#[test]
fn forces_from_two_parts_add_up_and_one_quantity_has_one_estimate_per_stage() {
    let config = Config::embedded_default().expect("defaults");
    let push = |f: f64| {
        Box::new(ConstantPush {
            force: f,
            updates: Arc::new(AtomicU64::new(0)),
            resets: Arc::new(AtomicU64::new(0)),
        })
    };
    let mut one = rig(&config, ControllerKind::C0);
    one.core.add_part(push(-60.0));
    let mut two = rig(&config, ControllerKind::C0);
    two.core.add_part(push(-20.0));
    two.core.add_part(push(-40.0));
    assert_eq!(one.tick_frozen(0..10), 0);
    assert_eq!(two.tick_frozen(0..10), 0);
    let (a, b) = (one.core.last.com_acc_cmd[0], two.core.last.com_acc_cmd[0]);
    assert!(
        (a - b).abs() < 1e-9 && a > 1e-3,
        "one part {a}, two parts {b}"
    );

    let mut r = rig(&config, ControllerKind::C1);
    r.core.add_part(Box::new(CopGuess("first_guess")));
    assert_eq!(r.tick_frozen(0..2), 0, "one estimate per stage is fine");
    r.core.add_part(Box::new(CopGuess("second_guess")));
    let e = r
        .tick(None)
        .expect_err("two estimates at one stage")
        .to_string();
    assert!(
        e.contains("`second_guess`")
            && e.contains("`first_guess`")
            && e.contains("centre of pressure"),
        "{e}"
    );
}

/// The record's columns have unique names (the CSV's header), and every part of the pipeline
/// is built for every controller.
#[test]
fn the_records_columns_are_unique_for_every_controller() {
    let config = Config::embedded_default().expect("defaults");
    for kind in [ControllerKind::C0, ControllerKind::C1, ControllerKind::C2] {
        let mut r = rig(&config, kind);
        assert_eq!(r.tick_frozen(0..3), 0);
        let mut rec = Record::default();
        r.core.record(&mut rec);
        assert_eq!(rec.overflow, 0);
        let names: Vec<_> = rec.columns().iter().map(|c| c.name).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{kind:?}: {names:?}");
        for part in ["corr_factor", "guard_x", "f_obs_x", "est_x"] {
            assert!(names.contains(&part), "{kind:?}: {part} missing");
        }
    }
    assert_eq!(PIPELINE.len(), 6);
}

/// A part's settings: a misspelt key is refused when the config is built, a value out of
/// range when the parts check it at load; both name the key and where it came from.
#[test]
fn a_parts_bad_settings_are_refused_at_load_naming_the_key_and_layer() {
    let layers = |set: &str| {
        let mut l = Config::default_layers().expect("layers");
        l.push_override(set).expect("override");
        l
    };
    let typo = layers("controller.wrist_tare.durration=0.2");
    let e = typo.build().expect_err("unknown key").to_string();
    assert!(
        e.contains("controller.wrist_tare.durration") && e.contains("--set"),
        "{e}"
    );
    let stray = layers("controller.no_such_part.enabled=true");
    let e = stray.build().expect_err("unknown table").to_string();
    assert!(e.contains("controller.no_such_part"), "{e}");
    // A renamed part's old table says what it is called now.
    let old = layers("controller.estimator.mode=\"on\"");
    let e = old.build().expect_err("renamed table").to_string();
    assert!(
        e.contains("controller.estimator") && e.contains("[controller.base_estimation]"),
        "{e}"
    );

    let range = layers("controller.forecast_correction.window=-1.0");
    let config = range.build().expect("well-formed");
    let e = upc::control::parts::check(&config, &range)
        .expect_err("out of range")
        .to_string();
    assert!(
        e.contains("controller.forecast_correction.window") && e.contains("--set"),
        "{e}"
    );
    let defaults = Config::default_layers().expect("layers");
    let config = defaults.build().expect("defaults");
    upc::control::parts::check(&config, &defaults).expect("the defaults pass every part's check");
}

/// A part's `Default` is its table of `config/default.toml`: the one home of its defaults.
#[test]
fn a_parts_defaults_are_the_embedded_config_files() {
    let toml: toml::Table = upc::config::DEFAULT_TOML.parse().expect("toml");
    let window = toml["controller"]["forecast_correction"]["window"]
        .as_float()
        .expect("window");
    let s = upc::control::CorrectionSettings::default();
    assert_eq!(s.window, window);
    let config = Config::embedded_default().expect("defaults");
    let from_config: upc::control::CorrectionSettings =
        config.controller.parts.get().expect("settings");
    assert_eq!(from_config, s);
}
