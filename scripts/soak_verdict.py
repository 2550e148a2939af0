#!/usr/bin/env python3
"""The soak's verdict (scripts/soak.sh): a table per report window, then whether RSS stays flat
after warm-up and misses do not grow.

    soak_verdict.py samples.csv controller.json REPORT_MINUTES
"""
import csv, json, sys
rows = [r for r in csv.DictReader(open(sys.argv[1]))]
s = json.load(open(sys.argv[2]))
# Per report window: RSS at its end, misses and ticks in it, the worst sample's tick p99 / max.
win = float(sys.argv[3]) * 60
print(f"  {'minutes':>9} {'RSS ctl kB':>11} {'RSS sim kB':>11} {'RSS fc kB':>10} {'ticks':>8} "
      f"{'misses':>7} {'tick p99 µs':>12} {'tick max µs':>12}")
prev, lo = {"ticks": "0", "deadline_misses": "0"}, 0.0
while lo < float(rows[-1]["t_s"]):
    part = [r for r in rows if lo < float(r["t_s"]) <= lo + win]
    if part:
        e = part[-1]
        print(f"  {lo / 60:4.0f}–{(lo + win) / 60:<4.0f} {e['rss_controller_kb']:>11} "
              f"{e['rss_sim_kb']:>11} {e['rss_forecaster_kb']:>10} "
              f"{int(e['ticks']) - int(prev['ticks']):>8} "
              f"{int(e['deadline_misses']) - int(prev['deadline_misses']):>7} "
              f"{max(int(r['tick_p99_us']) for r in part):>12} "
              f"{max(int(r['tick_max_us']) for r in part):>12}")
        prev = e
    lo += win
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
print(f"  balance: CoM height drop {1e3 * s['com_height_drop']:.1f} mm, min ZMP margin "
      f"{1e3 * s['min_zmp_margin']:.1f} mm, {s['time_at_support_edge']:.2f} s at the support edge, "
      f"QP fallbacks {s['wbc_fallbacks']}, C2 solves {s['c2_solves']} (failures {s['c2_failures']})")
# A soak that fell is a failed soak, whatever its memory and timing: the robot must still stand
# (the CoM within 2 cm of its height, the CoP inside the support).
stood = s["com_height_drop"] < 0.02 and s["min_zmp_margin"] > 0.0
ok &= stood
print(f"  the robot {'stood throughout' if stood else 'FELL'}")
# Ticks are the controller's: fewer than 90 % of the nominal 1 kHz means the machine could not
# run the loop at its rate (overloaded), which the misses alone understate.
secs = float(rows[-1]["t_s"]) - float(rows[0]["t_s"])
kept = s["ticks"] / max(1.0, 1000.0 * (float(rows[-1]["t_s"])))
print(f"  ticks at {100 * kept:.0f} % of the nominal rate over {secs:.0f} s of samples")
ok &= kept >= 0.9
print("soak: PASS" if ok else "soak: FAIL")
sys.exit(0 if ok else 1)
