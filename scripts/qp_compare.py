#!/usr/bin/env python3
"""The whole-body QP's condensed instances solved by PyPI solvers, against upc's answers.

Instances: `UPC_QP_EXPORT=/tmp/qp.jsonl cargo bench --bench wbc` (400 ticks: standing, pushed
at the hand, perturbed postures; `benches/wbc.rs`, `export_instances`). Each line holds the
QP as clarabel receives it (min ½xᵀPx + qᵀx, A x + s = b, s in 6 zeros then 8 second-order
cones of dimension 3) and upc's answer: its contact forces, whether the cone solve decided
(and its solve time),
and clarabel's iterations and solve time on that tick (from a controller that runs clarabel on
every tick).

Two problems:
- the QP as upc solves it (second-order friction cones): clarabel's Python wheel, the same
  solver as upc's;
- the cones replaced by inscribed 4-facet pyramids (|t_i·f| ≤ μ/√2 n·f), the form the QP-only
  solvers take (daqp, proxsuite, quadprog, osqp, piqp through qpsolvers; clarabel too, as the
  reference of that problem). Its optimum differs from the cone's wherever a cone is active.

Times: the best of 5 calls per instance, wall clock around the call (qpsolvers' conversion and
Python's call overhead included: measured alone below), p50 / p99 over the instances.

Install (outside the project's environment):
    python3 -m venv /tmp/qpenv && /tmp/qpenv/bin/pip install numpy scipy qpsolvers daqp \
        proxsuite quadprog osqp piqp clarabel
Run: /tmp/qpenv/bin/python scripts/qp_compare.py /tmp/qp.jsonl
"""

import json
import sys
import time

import numpy as np

TOL = 1e-6
REPEATS = 5


def load(path):
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def matrices(inst):
    n, m = inst["n"], inst["m"]
    p = np.array(inst["P"]).reshape(n, n)
    a = np.array(inst["A"]).reshape(m, n)
    return p, np.array(inst["q"]), a, np.array(inst["b"])


def best_time(f):
    best, out = float("inf"), None
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t0)
    return best, out


def forces(x, inst):
    return np.asarray(x[: 3 * inst["soc"]]) * inst["force_unit"]


def clarabel_cone(inst):
    """The QP with its second-order cones, clarabel's wheel, upc's settings."""
    import clarabel
    from scipy import sparse

    p, q, a, b = matrices(inst)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = TOL
    settings.presolve_enable = False
    settings.iterative_refinement_enable = False
    cones = [clarabel.ZeroConeT(inst["zero"])] + [
        clarabel.SecondOrderConeT(3) for _ in range(inst["soc"])
    ]
    pc, ac = sparse.csc_matrix(np.triu(p)), sparse.csc_matrix(a)

    def run():
        s = clarabel.DefaultSolver(pc, q, ac, b, cones, settings)
        sol = s.solve()
        return sol

    wall, sol = best_time(run)
    return sol.solve_time, wall, np.array(sol.x), sol.iterations


def pyramid(inst):
    """G x ≤ h and A_eq x = b_eq of the pyramid-linearised problem."""
    p, q, a, b = matrices(inst)
    z = inst["zero"]
    rows = []
    for c in range(inst["soc"]):
        r0 = a[z + 3 * c]
        for k in (1, 2):
            rk = a[z + 3 * c + k]
            # s = −A x here (b = 0): s0 = μ n·f, s_k = t_k·f; |s_k| ≤ s0/√2.
            rows.append(-rk + r0 / np.sqrt(2.0))
            rows.append(rk + r0 / np.sqrt(2.0))
    g = np.array(rows)
    return p, q, g, np.zeros(len(rows)), a[:z], b[:z]


def main():
    import qpsolvers

    everything = load(sys.argv[1])
    # Ticks at a torque limit are decided by the full problem: not this QP's optimum.
    inst = [i for i in everything if not i["torque_limited"]]
    solvers = [s for s in ["daqp", "proxqp", "quadprog", "osqp", "piqp", "clarabel"]
               if s in qpsolvers.available_solvers]
    rows = {}
    # Python and qpsolvers' own overhead: a 1-variable problem.
    overhead, _ = best_time(lambda: qpsolvers.solve_qp(
        np.eye(1), np.zeros(1), np.eye(1), np.ones(1), solver=solvers[0]))
    ref_pyr = []
    for i in inst:
        p, q, g, h, aeq, beq = pyramid(i)
        _, x = best_time(lambda: qpsolvers.solve_qp(
            p, q, g, h, aeq, beq, solver="clarabel", tol_gap_abs=1e-10, tol_gap_rel=1e-10,
            tol_feas=1e-10))
        ref_pyr.append(forces(x, i))
    for name in solvers:
        times, diffs, fails = [], [], 0
        kw = {"eps_abs": TOL, "eps_rel": TOL} if name in ("osqp", "proxqp", "piqp") else {}
        if name == "clarabel":
            kw = {"tol_gap_abs": TOL, "tol_gap_rel": TOL, "tol_feas": TOL}
        if name == "daqp":
            kw = {"primal_tol": TOL, "dual_tol": TOL}
        for i, ref in zip(inst, ref_pyr):
            p, q, g, h, aeq, beq = pyramid(i)
            t, x = best_time(lambda: qpsolvers.solve_qp(
                p, q, g, h, aeq, beq, solver=name, **kw))
            if x is None:
                fails += 1
                continue
            times.append(t)
            diffs.append(np.abs(forces(x, i) - ref).max())
        rows[name] = (times, diffs, fails)
    cone = [clarabel_cone(i) for i in inst]
    pct = lambda v, f: float(np.percentile(v, f)) * 1e6 if len(v) else float("nan")
    kinds = ", ".join(f"{k} {sum(i['kind'] == k for i in inst)}"
                      for k in sorted({i["kind"] for i in inst}))
    print(f"{len(inst)} instances of {len(everything)} (those at a torque limit left out; "
          f"{kinds}); qpsolvers + Python call overhead {overhead * 1e6:.1f} µs "
          f"(best of {REPEATS})")
    print()
    print("Second-order cones (upc's problem):")
    cl = [i for i in inst if not i["active_set"]]
    up = [i["clarabel_solve_us"] * 1e-6 for i in inst]
    tick = [i["clarabel_tick_us"] * 1e-6 for i in inst]
    print(f"  upc's clarabel (Rust, solver reused and updated in place, best of 5): solve p50 "
          f"{pct(up, 50):.1f} µs, p99 {pct(up, 99):.1f} µs, iterations p50 "
          f"{np.median([i['clarabel_iterations'] for i in inst]):.0f}; the whole-body tick "
          f"around it p50 {pct(tick, 50):.1f} µs")
    py_solve = [c[0] for c in cone]
    py_wall = [c[1] for c in cone]
    df = [np.abs(forces(c[2], i) - np.array(i["clarabel_forces"])).max() for c, i in zip(cone, inst)]
    print(f"  clarabel wheel (setup + solve, wall): p50 {pct(py_wall, 50):.1f} µs, p99 "
          f"{pct(py_wall, 99):.1f} µs (its own timer, setup included: p50 {pct(py_solve, 50):.1f} µs), "
          f"iterations p50 {np.median([c[3] for c in cone]):.0f}; "
          f"|Δf| to upc's clarabel max {max(df):.1e} N")
    das = [np.abs(np.array(i["forces"]) - np.array(i["clarabel_forces"])).max()
           for i in inst if i["active_set"]]
    at = [i["tick_us"] * 1e-6 for i in inst if i["active_set"]]
    ct = [i["tick_us"] * 1e-6 for i in inst if not i["active_set"]]
    cs = [i.get("solve_us", float("nan")) * 1e-6 for i in inst if i["active_set"]]
    print(f"  upc's cone solve decided {len(inst) - len(cl)} of {len(inst)}; |Δf| to clarabel "
          f"max {max(das) if das else float('nan'):.1e} N; its solve (best of 5) p50 "
          f"{pct(cs, 50):.1f} µs, p99 {pct(cs, 99):.1f} µs; upc's whole-body tick (best of 5) p50 "
          f"{pct(at, 50):.1f} µs on those, {pct(ct, 50):.1f} µs on the others")
    print()
    print("Pyramids (4 facets per corner), qpsolvers, wall per call, |Δf| to clarabel at 1e-10:")
    print("| solver | p50 (µs) | p99 (µs) | max |Δf| (N) | failures |")
    print("| --- | --- | --- | --- | --- |")
    for name, (times, diffs, fails) in rows.items():
        print(f"| {name} | {pct(times, 50):.1f} | {pct(times, 99):.1f} | "
              f"{max(diffs) if diffs else float('nan'):.1e} | {fails} |")
    # DAQP called directly, its own timers (setup + solve), without Python's overhead.
    try:
        import daqp

        own, dd = [], []
        for i, ref in zip(inst, ref_pyr):
            p, q, g, h, aeq, beq = pyramid(i)
            a = np.vstack([aeq, g])
            bu = np.concatenate([beq, h])
            bl = np.concatenate([beq, np.full(len(h), -1e30)])
            x, _, flag, info = daqp.solve(p, q, a, bu, bl, np.zeros(len(bu), dtype=np.int32))
            if flag >= 1:
                own.append(info["setup_time"] + info["solve_time"])
                dd.append(np.abs(forces(x, i) - ref).max())
        print(f"| daqp, its own timers (setup + solve) | {pct(own, 50):.1f} | {pct(own, 99):.1f} | "
              f"{max(dd):.1e} | {len(inst) - len(own)} |")
    except ImportError:
        pass
    cone_vs_pyr = [np.abs(np.array(i["clarabel_forces"]) - r).max() for i, r in zip(inst, ref_pyr)]
    print()
    print(f"The pyramids' optimum against the cones': |Δf| p50 {np.median(cone_vs_pyr):.2f} N, "
          f"max {max(cone_vs_pyr):.2f} N")


if __name__ == "__main__":
    main()
