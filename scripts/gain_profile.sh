#!/usr/bin/env bash
# C2's hand stiffness K_p over an impact under the conditions of the gain-profile question
# (docs/results/gain_profile.md): C2 on the full simulation, one impact, each condition a
# `upc run`; then the runs overlaid (`upc compare --overlay`) and K_p's mean per phase of the
# impact (before, onset = first 30 % of the rise, growing, fading, after).
#
#   scripts/gain_profile.sh [OUT]        (default runs/gain_profile; needs a release build)
set -euo pipefail
cd "$(dirname "$0")/.."
UPC="${UPC:-${CARGO_TARGET_DIR:-target}/release/upc}"
OUT="${1:-runs/gain_profile}"
mkdir -p "$OUT"
impact() { # name amplitude duration
  cat > "$OUT/$1.toml" <<TOML
name = "$1"
description = "One $2 N impact toward the robot, $3 s long, at t = 1 s"
duration = $(python3 -c "print(3.0 + $3)")
zmp_reference = [0.0, 0.0]

[force]
kind = "impacts"

[[force.impacts]]
start = 1.0
rise = $(python3 -c "print($3 / 2)")
hold = 0.0
fall = $(python3 -c "print($3 / 2)")
force = [-$2.0, 0.0, 0.0]
TOML
}
impact slow20 20 1.0    # far from C2's capability (67 N for a 1 s impact)
impact slow60 60 1.0    # near it
impact fast250 250 0.1  # near C2's capability for a 0.1 s impact (295 N)
run() { # name scenario args…
  local name=$1 scenario=$2; shift 2
  "$UPC" run --controller c2 --quiet --scenario "$OUT/$scenario.toml" --name "$name" --out "$OUT/runs" "$@" >/dev/null
}
run far slow20
run near slow60
run near_zmp_constraints slow60 --set preview.zmp_constraints=true
run near_R_x100 slow60 --set preview.r=5e-5
run near_forecast_x1.5 slow60 --forecast-error-scale 1.5
run near_forecast_late slow60 --forecast-error-shift 0.1
run near_forecast_early slow60 --forecast-error-shift -0.1
run fast fast250
run fast_zmp_term_only fast250 --set "gain_search.q_t=[0.0,0.0,0.0]" --set gain_search.s=0.0
"$UPC" compare --overlay --no-reduced --out "$OUT/slow" "$OUT"/runs/{far,near,near_*} >/dev/null
"$UPC" compare --overlay --no-reduced --out "$OUT/fast" "$OUT"/runs/fast* >/dev/null
python3 - "$OUT" <<'PY'
import csv, sys, pathlib
out = pathlib.Path(sys.argv[1])
print(f"{'condition':24} {'before':>7} {'onset':>7} {'growing':>8} {'fading':>7} {'after':>7}   K_p mean (1/s²)")
for run in sorted((out / "runs").iterdir()):
    d = 0.1 if run.name.startswith("fast") else 1.0
    rows = list(csv.DictReader(open(run / "c2" / "controller.csv")))
    def mean(a, b):
        v = [float(r["kp"]) for r in rows if a <= float(r["t"]) < b]
        return sum(v) / len(v)
    s, r = 1.0, d / 2
    phases = [(s - 0.3, s - 0.02), (s, s + 0.3 * r), (s + 0.3 * r, s + r), (s + r, s + 2 * r), (s + 2 * r, s + 2 * r + 0.5)]
    print(f"{run.name:24} " + " ".join(f"{mean(a, b):7.0f}" for a, b in phases))
PY
echo "figures: $OUT/slow/report.md, $OUT/fast/report.md"
