#!/usr/bin/env bash
# Soak test (not part of `cargo test`): controller + simulator + forecaster in real time at 1 kHz
# for a while, sampling each process's resident memory (VmRSS from /proc/<pid>/status) and the
# controller's deadline misses as it goes. Prints whether RSS stays flat and misses do not grow.
# See services/FAULTS.md.
#
#   scripts/soak.sh [minutes] [sample_seconds]      # default: 10 minutes, a sample every 5 s
#
# Environment: UPC (binary, default target/release/upc, built if missing), SOAK_DIR (output,
# default runs/soak-<time>), SOAK_ARGS (extra controller arguments, e.g. "--controller c2").
# Writes samples.csv (t, rss_kb per process, controller misses and ticks so far) and each
# process's log and summary in SOAK_DIR.
set -euo pipefail

minutes=${1:-10}
every=${2:-5}
root=$(cd "$(dirname "$0")/.." && pwd)
upc=${UPC:-$root/target/release/upc}
if [[ ! -x $upc ]]; then
    (cd "$root" && cargo build --release)
fi
dir=${SOAK_DIR:-$root/runs/soak-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$dir"
prefix="soak_$$"
duration=$(awk "BEGIN { print $minutes * 60 }")

# No push on the door: the robot stands for the whole soak (the impact scenarios end early).
cat >"$dir/quiet.toml" <<'EOF'
name = "quiet"
duration = 100000.0
zmp_reference = [0.0, 0.0]
[force]
kind = "impacts"
impacts = []
EOF

pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
    sleep 1
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

# The controller logs a status line (ticks, deadline misses) every `every` seconds
# (controller.status_every); the soak reads the newest from its log (see `status` below).
RUST_LOG=info "$upc" controller --realtime --scenario "$dir/quiet.toml" --duration 1e9 \
    --prefix "$prefix" --summary "$dir/controller.json" --set "controller.status_every=$every" \
    ${SOAK_ARGS:-} \
    2>"$dir/controller.log" &
pids+=($!)
ctl=$!
RUST_LOG=info "$upc" forecast --scenario "$dir/quiet.toml" --until 1e9 --prefix "$prefix" \
    2>"$dir/forecaster.log" &
pids+=($!)
fc=$!
RUST_LOG=info "$upc" sim --mode realtime --duration 0 --scenario "$dir/quiet.toml" \
    --prefix "$prefix" --summary "$dir/sim.json" 2>"$dir/sim.log" >"$dir/sim.out" &
pids+=($!)
sim=$!

rss() { awk '/^VmRSS:/ { print $2 }' "/proc/$1/status" 2>/dev/null || echo 0; }
# The newest "status: ticks T misses M" line of the controller's log.
status() {
    grep -a 'status: ticks' "$dir/controller.log" | tail -1 |
        sed -E 's/.*ticks ([0-9]+).*misses ([0-9]+).*/\1 \2/' || true
}

echo "soak: ${minutes} min in real time at 1 kHz, prefix $prefix, output $dir"
echo "t_s,rss_controller_kb,rss_sim_kb,rss_forecaster_kb,ticks,deadline_misses" >"$dir/samples.csv"
start=$(date +%s)
while :; do
    sleep "$every"
    now=$(($(date +%s) - start))
    for p in $ctl $sim $fc; do
        if ! kill -0 "$p" 2>/dev/null; then
            echo "soak: process $p exited early; see $dir/*.log" >&2
            exit 1
        fi
    done
    read -r ticks misses <<<"$(status)" || true
    line="$now,$(rss $ctl),$(rss $sim),$(rss $fc),${ticks:-0},${misses:-0}"
    echo "$line" >>"$dir/samples.csv"
    printf '\r  %4d s  RSS ctl %s kB  sim %s kB  fc %s kB  ticks %s  misses %s   ' \
        "$now" "$(rss $ctl)" "$(rss $sim)" "$(rss $fc)" "${ticks:-?}" "${misses:-?}"
    if awk "BEGIN { exit !($now >= $duration) }"; then break; fi
done
echo
kill -TERM $ctl $sim $fc
wait $ctl $sim $fc || true
pids=()

# Verdict: RSS over the second half vs. the first sample after start-up (the first minute or
# the first quarter, whichever is shorter, is warm-up); misses per minute, first vs. last third.
python3 - "$dir/samples.csv" "$dir/controller.json" <<'EOF'
import csv, json, sys
rows = [r for r in csv.DictReader(open(sys.argv[1]))]
s = json.load(open(sys.argv[2]))
t = [float(r["t_s"]) for r in rows]
warm = min(60.0, t[-1] / 4)
base = next(i for i, x in enumerate(t) if x >= warm)
ok = True
for p in ["controller", "sim", "forecaster"]:
    v = [int(r[f"rss_{p}_kb"]) for r in rows]
    b, e, peak = v[base], v[-1], max(v[base:])
    growth = (e - b) / b * 100 if b else 0.0
    flat = peak - b <= max(1024, 0.02 * b)  # within 1 MB or 2 % after warm-up
    ok &= flat
    print(f"  {p:<10} RSS start {v[0]} kB, after warm-up {b} kB, end {e} kB, peak {peak} kB "
          f"({growth:+.2f} %): {'flat' if flat else 'GROWS'}")
ticks = [int(r["ticks"]) for r in rows]
miss = [int(r["deadline_misses"]) for r in rows]
n = len(rows) // 3 or 1
def rate(a, b):  # misses per 1000 ticks between samples a and b
    dt = ticks[b] - ticks[a]
    return 1000.0 * (miss[b] - miss[a]) / dt if dt > 0 else 0.0
first, last = rate(0, n), rate(len(rows) - 1 - n, len(rows) - 1)
steady = last <= 2 * first + 1.0
ok &= steady
print(f"  controller ticks {s['ticks']}, deadline misses {s['deadline_misses']} "
      f"({1000.0 * s['deadline_misses'] / max(1, s['ticks']):.2f} per 1000 ticks), "
      f"tick p50 {s['tick_p50_us']:.0f} µs p99 {s['tick_p99_us']:.0f} µs max {s['tick_max_us']:.0f} µs")
print(f"  misses per 1000 ticks: first third {first:.2f}, last third {last:.2f}: "
      f"{'not growing' if steady else 'GROWING'}")
print(f"  stale periods {s['stale_periods']}, reconnects {s['reconnects']}, "
      f"dropped log records {s['dropped_log_records']}, tick errors {s['tick_errors']}")
print("soak: PASS" if ok else "soak: FAIL")
sys.exit(0 if ok else 1)
EOF
