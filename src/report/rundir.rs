//! A run directory written by `upc run`: `summary.json` and one `controller.csv` per controller.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::ReportError;
use super::series::CsvRun;

/// One controller's run inside a run directory.
#[derive(Debug, Clone)]
pub struct ControllerRun {
    /// "c0", "c1", "c2".
    pub name: String,
    pub csv: CsvRun,
    /// The controller's `ServerSummary` as JSON (absent if the controller failed).
    pub summary: Option<Value>,
    pub sim_summary: Option<Value>,
    pub wall_time: Option<f64>,
}

impl ControllerRun {
    /// A number from the controller's summary.
    pub fn stat(&self, key: &str) -> Option<f64> {
        self.summary.as_ref()?.get(key)?.as_f64()
    }
}

#[derive(Debug, Clone)]
pub struct RunDir {
    pub path: PathBuf,
    /// The directory's own name, used to name its figures.
    pub name: String,
    pub scenario: String,
    /// What `upc run --robot` was given (the default robot for runs that do not say).
    pub robot: String,
    /// The plant that ran it: `upc` (upc's own simulator, runs that do not say) or `mujoco`.
    pub plant: String,
    /// What `upc run --scenario` was given (an embedded name or a TOML path), if recorded.
    pub scenario_source: Option<String>,
    pub description: String,
    pub duration: f64,
    pub mode: String,
    /// The `--config` files and `--set` overrides of the run, if recorded.
    pub config_files: Vec<PathBuf>,
    pub config_sets: Vec<String>,
    pub controllers: Vec<ControllerRun>,
}

impl RunDir {
    pub fn load(path: &Path) -> Result<RunDir, ReportError> {
        let summary_path = path.join("summary.json");
        let text = std::fs::read_to_string(&summary_path).map_err(|source| ReportError::Io {
            path: summary_path.clone(),
            source,
        })?;
        let bad = |message: String| ReportError::Summary {
            path: summary_path.clone(),
            message,
        };
        let json: Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not valid JSON: {e}")))?;
        let str_of = |key: &str| json.get(key).and_then(Value::as_str).map(str::to_string);
        let scenario = str_of("scenario").ok_or_else(|| bad("no `scenario` string".into()))?;
        let duration = json
            .get("duration")
            .and_then(Value::as_f64)
            .ok_or_else(|| bad("no `duration` number".into()))?;
        let runs = json
            .get("runs")
            .and_then(Value::as_array)
            .ok_or_else(|| bad("no `runs` array".into()))?;
        let strings = |key: &str| -> Vec<String> {
            json.get(key)
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(Value::as_str)
                        .map(str::to_string)
                        .collect()
                })
                .unwrap_or_default()
        };
        let mut controllers = Vec::new();
        for (i, r) in runs.iter().enumerate() {
            let name = r
                .get("controller")
                .and_then(Value::as_str)
                .ok_or_else(|| bad(format!("runs[{i}] has no `controller` string")))?;
            // Not `name` with separators or `..`: it names a subdirectory of this run.
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(bad(format!("runs[{i}].controller `{name}` is not a name")));
            }
            // The CSV beside the summary, not the recorded path: run directories can be moved.
            let csv = CsvRun::read(
                &path.join(name).join("controller.csv"),
                &name.to_uppercase(),
            )?;
            let non_null = |v: Option<&Value>| v.filter(|v| !v.is_null()).cloned();
            controllers.push(ControllerRun {
                name: name.to_string(),
                csv,
                summary: non_null(r.get("controller_summary")),
                sim_summary: non_null(r.get("sim_summary")),
                wall_time: r.get("wall_time").and_then(Value::as_f64),
            });
        }
        if controllers.is_empty() {
            return Err(bad("`runs` is empty".into()));
        }
        Ok(RunDir {
            name: path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "run".into()),
            path: path.to_path_buf(),
            scenario,
            robot: str_of("robot").unwrap_or_else(|| crate::robot::DEFAULT.into()),
            plant: str_of("plant").unwrap_or_else(|| "upc".into()),
            scenario_source: str_of("scenario_source"),
            description: str_of("description").unwrap_or_default(),
            duration,
            mode: str_of("mode").unwrap_or_else(|| "?".into()),
            config_files: strings("config_files")
                .into_iter()
                .map(PathBuf::from)
                .collect(),
            config_sets: strings("config_sets"),
            controllers,
        })
    }
}
