#!/usr/bin/env bash
# Soak test (not part of `cargo test`): controller + simulator + forecaster in real time at 1 kHz
# for a while, the multiple-impact scenario's four pushes repeated every 8 s all along, sampling
# each process's resident memory (VmRSS from /proc/<pid>/status) and the controller's deadline
# misses and tick p99 as it goes. Prints a table per `report` minutes, and whether RSS stays flat
# and misses do not grow. See services/FAULTS.md.
#
#   scripts/soak.sh [minutes] [sample_seconds] [report_minutes]   # default: 10, 5 s, 5 min
#
# Environment: UPC (binary, default target/release/upc, built if missing), SOAK_DIR (output,
# default runs/soak-<time>), SOAK_PLANT (upc or mujoco; default upc), SOAK_ARGS (controller
# arguments; default "--controller c2"), SOAK_QUIET=1 (no push: the robot only stands),
# SOAK_RT=1 (as the services/ units deploy it: the controller with config/realtime.toml, FIFO
# and pinned, the plant and the forecaster at SCHED_FIFO 70 through chrt; needs CAP_SYS_NICE).
# Writes samples.csv (t, rss_kb per process, the controller's ticks and misses so far, its tick
# p99 and max over the ticks since the previous sample) and each process's log and summary in
# SOAK_DIR.
set -euo pipefail

minutes=${1:-10}
every=${2:-5}
report=${3:-5}
plant=${SOAK_PLANT:-upc}
ctl_args=${SOAK_ARGS:---controller c2}
root=$(cd "$(dirname "$0")/.." && pwd)
upc=${UPC:-$root/target/release/upc}
if [[ ! -x $upc ]]; then
    (cd "$root" && cargo build --release)
fi
dir=${SOAK_DIR:-$root/runs/soak-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$dir"
prefix="soak_$$"
duration=$(awk "BEGIN { print $minutes * 60 }")

# The scenario: multiple_impacts' pushes every 8 s for the whole soak (none with SOAK_QUIET=1).
python3 "$root/scripts/soak_scenario.py" "$root/config/scenarios/multiple_impacts.toml" \
    "$duration" "${SOAK_QUIET:-0}" >"$dir/soak.toml"

ctl_rt=()
rt=()
if [[ ${SOAK_RT:-0} == 1 ]]; then
    ctl_rt=(--config "$root/config/realtime.toml")
    rt=(chrt -f 70)
fi

pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
    sleep 1
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

# The controller logs a status line (ticks, deadline misses, the tick p99 since the last line)
# every `every` seconds (controller.status_every); the soak reads the newest from its log.
# shellcheck disable=SC2086 # ctl_args is a list of arguments
RUST_LOG=info "$upc" controller --realtime --scenario "$dir/soak.toml" --duration 1e9 \
    --prefix "$prefix" --summary "$dir/controller.json" --set "controller.status_every=$every" \
    "${ctl_rt[@]}" $ctl_args \
    2>"$dir/controller.log" &
pids+=($!)
ctl=$!
RUST_LOG=info "${rt[@]}" "$upc" forecast --scenario "$dir/soak.toml" --until 1e9 --prefix "$prefix" \
    2>"$dir/forecaster.log" &
pids+=($!)
fc=$!
RUST_LOG=info "${rt[@]}" "$upc" sim --plant "$plant" --mode realtime --duration 0 \
    --scenario "$dir/soak.toml" --prefix "$prefix" --summary "$dir/sim.json" \
    2>"$dir/sim.log" >"$dir/sim.out" &
pids+=($!)
sim=$!

rss() { awk '/^VmRSS:/ { print $2 }' "/proc/$1/status" 2>/dev/null || echo 0; }
# The newest status line of the controller's log: ticks, misses, tick p99 and max (µs).
status() {
    grep -a 'status: ticks' "$dir/controller.log" | tail -1 |
        sed -E 's/.*ticks ([0-9]+) misses ([0-9]+).*window_tick_p99_us ([0-9]+) window_tick_max_us ([0-9]+).*/\1 \2 \3 \4/' ||
        true
}

echo "soak: ${minutes} min in real time at 1 kHz, $plant plant, controller $ctl_args, prefix $prefix, output $dir"
echo "t_s,rss_controller_kb,rss_sim_kb,rss_forecaster_kb,ticks,deadline_misses,tick_p99_us,tick_max_us" \
    >"$dir/samples.csv"
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
    read -r ticks misses p99 tmax <<<"$(status)" || true
    echo "$now,$(rss $ctl),$(rss $sim),$(rss $fc),${ticks:-0},${misses:-0},${p99:-0},${tmax:-0}" \
        >>"$dir/samples.csv"
    printf '\r  %4d s  RSS ctl %s kB  sim %s kB  fc %s kB  ticks %s  misses %s  tick p99 %s µs   ' \
        "$now" "$(rss $ctl)" "$(rss $sim)" "$(rss $fc)" "${ticks:-?}" "${misses:-?}" "${p99:-?}"
    if awk "BEGIN { exit !($now >= $duration) }"; then break; fi
done
echo
kill -TERM $ctl $sim $fc
wait $ctl $sim $fc || true
pids=()

python3 "$root/scripts/soak_verdict.py" "$dir/samples.csv" "$dir/controller.json" "$report"
