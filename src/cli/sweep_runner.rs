//! What runs a sweep's cells ([`CellArgs`]): threads on this machine (`--engine local`, `--jobs`
//! at a time) or Ray (`--engine ray`, one task per cell, on a cluster; scripts/ray_sweep.py is
//! the driver). Either way each finished cell is saved under `<out>/cells/` as soon as it is
//! done, and a sweep started again with the same `--out` runs only the cells not saved yet
//! (docs/sweeps.md).

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::ProgressBar;
use sha2::{Digest, Sha256};

use super::BoxError;
use super::cell::{CellArgs, CellResult, Outcome, search};

/// The Ray driver, carried in the binary so that an installed `upc` needs no source tree.
const RAY_DRIVER: &str = include_str!("../../scripts/ray_sweep.py");

#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, clap::ValueEnum)]
pub enum RunnerKind {
    /// Threads of this process, each running its cell's cases as `upc run` processes.
    #[default]
    Local,
    /// One Ray task per cell, each running `upc sweep-cell` with one CPU reserved.
    Ray,
}

#[derive(clap::Args, Debug, Clone, Default)]
pub struct RunnerArgs {
    /// What runs the cells: this machine (`local`), or Ray (`ray`: the cluster at
    /// `--ray-address`, else `$RAY_ADDRESS`, else a local Ray cluster started for the sweep).
    #[arg(long, value_enum, default_value = "local")]
    pub engine: RunnerKind,
    /// Cells run at once on this machine (default: its cores); with `--engine ray` and no
    /// cluster to join, the CPUs of the local cluster.
    #[arg(long)]
    pub jobs: Option<usize>,
    /// The Ray cluster to join: its head's HOST:PORT (what `ray start --head` prints).
    #[arg(long)]
    pub ray_address: Option<String>,
}

impl RunnerArgs {
    /// Cells run at once on this machine.
    pub fn jobs(&self) -> usize {
        self.jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1)
    }

    /// How the report names the engine (the Ray cluster as the driver of the sweep in `out`
    /// saw it).
    pub fn describe(&self, out: &Path) -> String {
        match self.engine {
            RunnerKind::Local => format!("{} at a time", count(self.jobs() as u64, "cell")),
            RunnerKind::Ray => match ray_cluster(out) {
                Some(c) => {
                    let n = |k: &str| c.get(k).and_then(serde_json::Value::as_u64).unwrap_or(0);
                    format!(
                        "on Ray ({}, {}), one task per cell",
                        count(n("nodes"), "node"),
                        count(n("cpus"), "CPU")
                    )
                }
                None => "on Ray, one task per cell".to_string(),
            },
        }
    }
}

/// Runs a sweep's cells on the engine `--engine` chose, and saves them under `out`.
pub struct SweepRunner<'a> {
    pub args: &'a RunnerArgs,
    pub out: &'a Path,
    /// The `upc` every case runs.
    pub exe: &'a Path,
    /// Counts the cases run (the local engine), `per_cell` per cell at most.
    pub bar: &'a ProgressBar,
    pub per_cell: u64,
    pub quiet: bool,
}

/// A cell's saved result (`<out>/cells/<key>.json`): the cell, as its command line, and what it
/// gave.
#[derive(serde::Serialize, serde::Deserialize)]
struct Saved {
    argv: Vec<String>,
    result: CellResult,
}

impl SweepRunner<'_> {
    /// Every cell's result, in the order of `cells`: those already searched under `out` are
    /// read back, the others run (a failed cell too: what made it fail may have been mended).
    pub fn run(&self, cells: &[CellArgs]) -> Result<Vec<CellResult>, BoxError> {
        let dir = self.out.join("cells");
        std::fs::create_dir_all(&dir)?;
        let build = build_id(self.exe)?;
        let store = Store {
            dir: &dir,
            build: &build,
        };
        let mut results: Vec<Option<CellResult>> =
            cells.iter().map(|c| store.searched(c)).collect();
        let pending: Vec<usize> = (0..cells.len()).filter(|&i| results[i].is_none()).collect();
        let resumed = cells.len() - pending.len();
        if resumed > 0 {
            self.bar.inc(resumed as u64 * self.per_cell);
            eprintln!(
                "sweep: {resumed} of {} cells already done in {} (not run again)",
                cells.len(),
                dir.display()
            );
        }
        if !pending.is_empty() {
            let todo: Vec<&CellArgs> = pending.iter().map(|&i| &cells[i]).collect();
            match self.args.engine {
                RunnerKind::Local => self.run_local(&todo, &store)?,
                RunnerKind::Ray => self.run_ray(&todo, &store)?,
            }
            for &i in &pending {
                results[i] = Some(store.saved(&cells[i]).ok_or_else(|| {
                    format!(
                        "the engine returned without the result of {}",
                        cells[i].argv().join(" ")
                    )
                })?);
            }
        }
        Ok(results.into_iter().flatten().collect())
    }

    /// The pending cells, `--jobs` at a time, each saved when done.
    fn run_local(&self, todo: &[&CellArgs], store: &Store) -> Result<(), BoxError> {
        let scratch = self.out.join("cases");
        std::fs::create_dir_all(&scratch)?;
        pool(todo, self.args.jobs(), |cell| {
            let result = search(self.exe, cell, &scratch, &|| self.bar.inc(1));
            let runs = match &result.outcome {
                Outcome::Searched { capability, .. } => capability.runs as u64,
                Outcome::Failed { .. } => 0,
            };
            // The bar counted the longest search: settle the difference.
            self.bar.inc(self.per_cell.saturating_sub(runs));
            store.save(cell, result)
        })?;
        Ok(())
    }

    /// The pending cells as Ray tasks: the driver saves each result as it arrives.
    fn run_ray(&self, todo: &[&CellArgs], store: &Store) -> Result<(), BoxError> {
        let dir = store.dir;
        let ray_dir = self.out.join("ray");
        std::fs::create_dir_all(&ray_dir)?;
        let list = ray_dir.join("cells.jsonl");
        let mut lines = String::new();
        for cell in todo {
            lines += &serde_json::to_string(&serde_json::json!({
                "key": store.key(cell),
                "argv": cell.argv(),
            }))?;
            lines.push('\n');
        }
        std::fs::write(&list, lines)?;
        let mut cmd = Command::new(super::common::python(&None));
        cmd.arg("-c")
            .arg(RAY_DRIVER)
            .arg("--upc")
            .arg(self.exe)
            .arg("--cells")
            .arg(&list)
            .arg("--results")
            .arg(dir)
            .arg("--cluster-info")
            .arg(ray_dir.join("runs.jsonl"));
        if let Some(a) = &self.args.ray_address {
            cmd.arg("--address").arg(a);
        }
        if let Some(j) = self.args.jobs {
            cmd.arg("--num-cpus").arg(j.to_string());
        }
        if self.quiet {
            cmd.arg("--quiet");
        }
        super::child::stopped_with_parent(&mut cmd);
        let status = cmd
            .status()
            .map_err(|e| format!("cannot start the Ray driver ({:?}): {e}", cmd.get_program()))?;
        if !status.success() {
            return Err(format!(
                "the Ray driver failed ({status}); the cells done so far are saved in {}: run \
                 the same command again to go on",
                dir.display()
            )
            .into());
        }
        Ok(())
    }
}

/// "1 cell", "2 cells".
fn count(n: u64, what: &str) -> String {
    if n == 1 {
        format!("1 {what}")
    } else {
        format!("{n} {what}s")
    }
}

/// The `upc` build that runs a sweep's cases: the SHA-256 of its executable (the embedded
/// defaults, robots and scenarios included).
fn build_id(exe: &Path) -> Result<String, BoxError> {
    let bytes = std::fs::read(exe)
        .map_err(|e| format!("cannot read {} to name its build: {e}", exe.display()))?;
    Ok(hex(&Sha256::digest(&bytes)))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The saved cells of a sweep run by one build (`<out>/cells/`).
struct Store<'a> {
    dir: &'a Path,
    build: &'a str,
}

impl Store<'_> {
    /// A cell's name under the store: a digest of the build, the cell's command line and the
    /// contents of the files that command line names (config files, a robot description file;
    /// not the files those name). A result is read back only for what produced it: after a new
    /// build or an edited config file the sweep runs its cells again.
    fn key(&self, cell: &CellArgs) -> String {
        let mut h = Sha256::new();
        h.update(self.build.as_bytes());
        h.update(b"\0");
        h.update(cell.argv().join("\0").as_bytes());
        let robot = Path::new(&cell.setup.robot.robot);
        let named = cell.setup.config.configs.iter().map(|p| p.as_path());
        for file in named.chain(robot.is_file().then_some(robot)) {
            h.update(b"\0");
            h.update(std::fs::read(file).unwrap_or_default());
        }
        hex(&h.finalize()[..8])
    }

    /// `cell`'s saved result, if one is saved for exactly this cell.
    fn saved(&self, cell: &CellArgs) -> Option<CellResult> {
        let path = self.dir.join(format!("{}.json", self.key(cell)));
        let s: Saved = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
        (s.argv == cell.argv()).then_some(s.result)
    }

    /// `cell`'s saved result if it was searched (a failed cell is run again by a new sweep).
    fn searched(&self, cell: &CellArgs) -> Option<CellResult> {
        self.saved(cell)
            .filter(|r| matches!(r.outcome, Outcome::Searched { .. }))
    }

    /// Saves `result` for `cell`, whole or not at all (written aside, then renamed).
    fn save(&self, cell: &CellArgs, result: CellResult) -> Result<(), BoxError> {
        let k = self.key(cell);
        let tmp = self.dir.join(format!(".{k}.json.tmp"));
        let text = serde_json::to_string_pretty(&Saved {
            argv: cell.argv(),
            result,
        })?;
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, self.dir.join(format!("{k}.json")))?;
        Ok(())
    }
}

/// The Ray cluster as the driver saw it last (`<out>/ray/runs.jsonl`, a line per driver run),
/// if it ran.
fn ray_cluster(out: &Path) -> Option<HashMap<String, serde_json::Value>> {
    let text = std::fs::read_to_string(out.join("ray/runs.jsonl")).ok()?;
    serde_json::from_str(text.lines().last()?).ok()
}

/// `f` of each item, `jobs` threads at a time taking the items in order; the results in the
/// items' order. The first error stops the pool (items already started finish).
pub fn pool<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    f: impl Fn(&T) -> Result<R, BoxError> + Sync,
) -> Result<Vec<R>, BoxError> {
    let next = AtomicUsize::new(0);
    let results = Mutex::new((0..items.len()).map(|_| None).collect::<Vec<Option<R>>>());
    let first_error = Mutex::new(None::<String>);
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(item) = items.get(i) else { return };
                    match f(item) {
                        Ok(r) => results.lock().unwrap_or_else(|p| p.into_inner())[i] = Some(r),
                        Err(e) => {
                            first_error
                                .lock()
                                .unwrap_or_else(|p| p.into_inner())
                                .get_or_insert(e.to_string());
                            // No further item is taken.
                            next.store(items.len(), Ordering::Relaxed);
                            return;
                        }
                    }
                }
            });
        }
    });
    if let Some(e) = first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e.into());
    }
    Ok(results
        .into_inner()
        .unwrap_or_else(|p| p.into_inner())
        .into_iter()
        .flatten()
        .collect())
}

/// The sweep's end once its outputs are written: an error naming each failed cell and why.
pub fn failed_cells(failed: &[(String, String)]) -> super::CliResult {
    if failed.is_empty() {
        return Ok(());
    }
    let list: Vec<String> = failed
        .iter()
        .map(|(cell, why)| format!("  {cell}\n    {why}"))
        .collect();
    Err(format!(
        "{} failed (not on the map, never counted as survived):\n{}",
        count(failed.len() as u64, "cell"),
        list.join("\n")
    )
    .into())
}

/// The failed cells in a report's JSON.
pub fn failed_json(failed: &[(String, String)]) -> serde_json::Value {
    failed
        .iter()
        .map(|(cell, why)| serde_json::json!({ "cell": cell, "reason": why }))
        .collect()
}

/// The report's section of failed cells (none: nothing written).
pub fn failed_section(md: &mut String, failed: &[(String, String)]) {
    if failed.is_empty() {
        return;
    }
    md.push_str(
        "## Cells that failed\n\nThese cells could not run (not on the map below, never \
         counted as survived):\n\n| cell | reason |\n|---|---|\n",
    );
    for (cell, why) in failed {
        md.push_str(&format!("| `{cell}` | {} |\n", why.replace('|', "\\|")));
    }
    md.push('\n');
}
