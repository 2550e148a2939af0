//! Time series of one controller's run, from a full-simulation CSV or from the reduced-model
//! loop, behind one trait so that every figure is drawn by the same code.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::ReportError;
use super::csv::{Columns, Reading};
use crate::offline::RunResult;

/// What a figure can plot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quantity {
    /// The ZMP the run is judged on: measured (centre of pressure) in the full simulation, the
    /// cart-table ZMP in the reduced models.
    ZmpX,
    ZmpY,
    /// The ZMP the preview predicts one preview step ahead (full simulation only).
    ZmpPredX,
    ZmpPredY,
    ZmpRefX,
    ZmpRefY,
    /// ‖hand − set-point‖ (m).
    HandError,
    ComX,
    ComY,
    ComZ,
    Kp,
    FExtX,
    FExtY,
    FExtZ,
    FDisX,
    FDisY,
    FDisZ,
    /// Largest impact survived (N), against the impact's duration (`upc capability`).
    MaxForce,
}

/// One controller's time series.
pub trait SeriesSource {
    /// Legend label, e.g. "C1".
    fn label(&self) -> &str;
    /// Sample times (s).
    fn time(&self) -> &[f64];
    /// The samples of `q`, one per time, or `None` if this source does not have it.
    fn values(&self, q: Quantity) -> Option<&[f64]>;
    /// Support rectangle [[x_min, x_max], [y_min, y_max]] in the frame of the ZMP, if known.
    fn support(&self) -> Option<[[f64; 2]; 2]>;
}

/// One controller's columns by quantity: the store behind both kinds of run.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    t: Vec<f64>,
    columns: HashMap<Quantity, Vec<f64>>,
    support: Option<[[f64; 2]; 2]>,
}

impl Series {
    /// A series of given columns over `t` (which need not be time: a capability curve's is
    /// the impact duration).
    pub fn from_columns(label: &str, t: Vec<f64>, columns: Vec<(Quantity, Vec<f64>)>) -> Series {
        Series {
            label: label.to_string(),
            t,
            columns: columns.into_iter().collect(),
            support: None,
        }
    }
}

impl SeriesSource for Series {
    fn label(&self) -> &str {
        &self.label
    }
    fn time(&self) -> &[f64] {
        &self.t
    }
    fn values(&self, q: Quantity) -> Option<&[f64]> {
        self.columns.get(&q).map(Vec::as_slice)
    }
    fn support(&self) -> Option<[[f64; 2]; 2]> {
        self.support
    }
}

/// `controller.csv` of one full-simulation run, read by column name.
#[derive(Debug, Clone)]
pub struct CsvRun {
    pub path: PathBuf,
    pub series: Series,
    /// Raw columns by name, for metrics computed here (e.g. `com_z`).
    raw: Columns,
}

/// The reading of `controller.csv`: strict, with the columns without which a run cannot be
/// plotted at all.
const STRICT: Reading = Reading::Strict {
    required: &["t", "zmp_meas_x", "zmp_meas_y", "hand_err"],
};

const COLUMNS: [(&str, Quantity); 17] = [
    ("zmp_meas_x", Quantity::ZmpX),
    ("zmp_meas_y", Quantity::ZmpY),
    ("zmp_pred_x", Quantity::ZmpPredX),
    ("zmp_pred_y", Quantity::ZmpPredY),
    ("zmp_ref_x", Quantity::ZmpRefX),
    ("zmp_ref_y", Quantity::ZmpRefY),
    ("hand_err", Quantity::HandError),
    ("com_x", Quantity::ComX),
    ("com_y", Quantity::ComY),
    ("com_z", Quantity::ComZ),
    ("kp", Quantity::Kp),
    ("f_ext_x", Quantity::FExtX),
    ("f_ext_y", Quantity::FExtY),
    ("f_ext_z", Quantity::FExtZ),
    ("f_dis_x", Quantity::FDisX),
    ("f_dis_y", Quantity::FDisY),
    ("f_dis_z", Quantity::FDisZ),
];

impl CsvRun {
    /// Read `path`; every error names the file (and the line for a bad value).
    pub fn read(path: &Path, label: &str) -> Result<CsvRun, ReportError> {
        Self::from_columns(Columns::read(path, STRICT)?, path, label)
    }

    pub fn parse(text: &str, path: &Path, label: &str) -> Result<CsvRun, ReportError> {
        Self::from_columns(Columns::parse(text, path, STRICT)?, path, label)
    }

    /// The run of columns read strictly (so `t` is there).
    fn from_columns(raw: Columns, path: &Path, label: &str) -> Result<CsvRun, ReportError> {
        let columns = COLUMNS
            .iter()
            .filter_map(|(name, q)| raw.get(name).map(|v| (*q, v.clone())))
            .collect();
        // The core latches the support at its first tick: any finite row holds it.
        let support = ["sup_x_min", "sup_x_max", "sup_y_min", "sup_y_max"]
            .iter()
            .map(|n| {
                raw.get(n)
                    .and_then(|v| v.iter().copied().find(|x| x.is_finite()))
            })
            .collect::<Option<Vec<f64>>>()
            .map(|s| [[s[0], s[1]], [s[2], s[3]]]);
        let t = raw.get("t").cloned().ok_or_else(|| ReportError::Csv {
            path: path.to_path_buf(),
            line: 1,
            message: "no `t` column in the header".into(),
        })?;
        Ok(CsvRun {
            path: path.to_path_buf(),
            series: Series {
                label: label.to_string(),
                t,
                columns,
                support,
            },
            raw,
        })
    }

    /// A raw column by its CSV name.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.raw.get(name).map(Vec::as_slice)
    }
}

/// A reduced-model run, its rows laid out as columns.
#[derive(Debug, Clone)]
pub struct ReducedRun {
    pub result: RunResult,
    pub series: Series,
}

impl ReducedRun {
    pub fn new(result: RunResult, support: [[f64; 2]; 2]) -> ReducedRun {
        let rows = &result.rows;
        let col = |f: &dyn Fn(&crate::offline::Row) -> f64| rows.iter().map(f).collect::<Vec<_>>();
        let columns = HashMap::from([
            (Quantity::ZmpX, col(&|r| r.zmp[0])),
            (Quantity::ZmpY, col(&|r| r.zmp[1])),
            (Quantity::ZmpRefX, col(&|r| r.zmp_ref[0])),
            (Quantity::ZmpRefY, col(&|r| r.zmp_ref[1])),
            (Quantity::HandError, col(&|r| r.hand_error)),
            (Quantity::ComX, col(&|r| r.com[0])),
            (Quantity::ComY, col(&|r| r.com[1])),
            (Quantity::Kp, col(&|r| r.kp)),
            (Quantity::FExtX, col(&|r| r.f_ext[0])),
            (Quantity::FExtY, col(&|r| r.f_ext[1])),
            (Quantity::FExtZ, col(&|r| r.f_ext[2])),
            (Quantity::FDisX, col(&|r| r.f_dis[0])),
            (Quantity::FDisY, col(&|r| r.f_dis[1])),
            (Quantity::FDisZ, col(&|r| r.f_dis[2])),
        ]);
        ReducedRun {
            series: Series {
                label: result.controller.name().to_uppercase(),
                t: col(&|r| r.t),
                columns,
                support: Some(support),
            },
            result,
        }
    }
}
