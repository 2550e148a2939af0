"""The Ray driver of upc's sweeps (`upc capability` / `upc robustness --engine ray`).

`upc` runs this with the cells to search (one JSON line each: its key and its `upc sweep-cell`
command line). Each cell becomes one Ray task that reserves one CPU and runs `upc sweep-cell` as
a subprocess on whichever node Ray picks; the task hands the cell's result (JSON) back and this
driver saves it under `--results` at once, so a driver stopped and started again redoes only the
cells not saved. docs/sweeps.md says why a task is a cell and not a run.

Faults:
- a node that dies takes its tasks with it: Ray runs them again elsewhere (`max_retries`);
- a cell that fails by itself (the plant refuses it, `upc` crashes) is a result, "failed" with
  its reason: returned, saved and reported once, never retried (`retry_exceptions` is off and
  the task does not raise);
- a worker whose `upc` is another build than the driver's refuses the task: the sweep stops
  with a message naming the node (results saved so far are kept);
- the subprocess dies with its task's worker (PR_SET_PDEATHSIG), and `upc` does the same for
  its own children, so a killed worker leaves no `upc` behind.

With no `--address` (and no RAY_ADDRESS) a local cluster is started for the sweep, its node on
loopback: Ray turns 127.0.0.1 into the host's outward address, so 127.0.0.2 is used
(UPC_RAY_NODE_IP to change it; when joining a cluster, it names this host's address on it).
"""

import argparse
import ctypes
import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time

import ray

PR_SET_PDEATHSIG = 1
_build_ids = {}


def build_id(path):
    """SHA-256 of the executable, cached per worker process by size and modification time."""
    st = os.stat(path)
    stamp = (path, st.st_size, st.st_mtime_ns)
    if stamp not in _build_ids:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _build_ids[stamp] = h.hexdigest()
    return _build_ids[stamp]


def die_with_parent():
    """In the child before exec: SIGKILL when the worker that started it dies."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


@ray.remote(num_cpus=1, max_retries=3, retry_exceptions=False)
def run_cell(upc, build, argv):
    """One cell: `upc sweep-cell` on this node; its result, a refusal, or a failure."""
    host = f"{socket.gethostname()} ({ray.util.get_node_ip_address()})"
    exe = os.environ.get("UPC_EXE", upc)
    if not os.access(exe, os.X_OK):
        return {"refused": f"node {host} has no upc at {exe}: put the binary on a shared "
                           "filesystem at the same path, or set UPC_EXE on the node"}
    mine = build_id(exe)
    if mine != build:
        return {"refused": f"node {host} runs another upc build ({exe}: sha256 {mine[:12]}, "
                           f"the sweep's is {build[:12]}): give every node the driver's binary"}
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="upc-cell-") as scratch:
        p = subprocess.run([exe, *argv, "--scratch", scratch], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, preexec_fn=die_with_parent,
                           env={**os.environ, "RUST_LOG": "warn"})
    took = time.monotonic() - t0
    if p.returncode != 0:
        last = next((l for l in reversed(p.stderr.splitlines()) if l.strip()), "")
        why = (f"killed by signal {-p.returncode}" if p.returncode < 0
               else f"exited with {p.returncode}")
        return {"result": {"outcome": {"failed": {"reason": f"upc sweep-cell {why} on {host}: {last}"}},
                           "wall_time": took}, "task_time": took}
    return {"result": json.loads(p.stdout), "task_time": took, "node": host}


def save(results, key, argv, result):
    tmp = os.path.join(results, f".{key}.json.tmp")
    with open(tmp, "w") as f:
        json.dump({"argv": argv, "result": result}, f, indent=2)
    os.replace(tmp, os.path.join(results, f"{key}.json"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--upc", required=True)
    ap.add_argument("--cells", required=True)
    ap.add_argument("--results", required=True)
    ap.add_argument("--cluster-info", required=True)
    ap.add_argument("--address")
    ap.add_argument("--num-cpus", type=int)
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args()
    cells = [json.loads(l) for l in open(a.cells) if l.strip()]
    address = a.address or os.environ.get("RAY_ADDRESS")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    # Ray's own default today, without its warning about the default changing.
    os.environ.setdefault("RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO", "0")
    # The driver exports no metrics (a cluster without its dashboard has no agent to take them).
    os.environ.setdefault("RAY_enable_metrics_collection", "0")
    t_start = time.monotonic()
    if address:
        # This host's address on the cluster: Ray's guess unless UPC_RAY_NODE_IP says.
        ray.init(address=address, logging_level="WARNING", log_to_driver=False,
                 _node_ip_address=os.environ.get("UPC_RAY_NODE_IP"))
    else:
        # "local": a new cluster even where `ray start` left one (or its stale address file).
        ray.init(address="local", num_cpus=a.num_cpus, include_dashboard=False,
                 logging_level="WARNING", log_to_driver=False,
                 _node_ip_address=os.environ.get("UPC_RAY_NODE_IP", "127.0.0.2"))
    t_ready = time.monotonic()
    # Stopped (upc, its parent, gone: PR_SET_PDEATHSIG): exit through Ray's own shutdown, which
    # stops the local cluster's processes and, through them, the tasks' `upc`s. Set after
    # ray.init, whose own handler only reports the signal.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    cpus = int(ray.cluster_resources().get("CPU", 1))
    nodes = sum(1 for n in ray.nodes() if n.get("Alive"))
    info = {"address": address or "local", "nodes": nodes, "cpus": cpus,
            "start_time": t_ready - t_start, "cells": len(cells)}
    build = build_id(a.upc)
    pending = {}
    for c in cells:
        ref = run_cell.remote(a.upc, build, c["argv"])
        pending[ref] = (c, time.monotonic())
    done = failed = lost = 0
    task_times, overheads = [], []
    last_print = 0.0
    refused = None
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1, timeout=2.0)
        for ref in ready:
            c, _submitted = pending.pop(ref)
            try:
                r = ray.get(ref)
            except Exception as e:  # the task's node died more times than Ray retries
                lost += 1
                print(f"ray_sweep: cell {c['key']} lost: {type(e).__name__}: {e}",
                      file=sys.stderr)
                continue
            if "refused" in r:
                refused = r["refused"]
                continue
            save(a.results, c["key"], c["argv"], r["result"])
            done += 1
            task_times.append(r["task_time"])
            overheads.append(r["task_time"] - r["result"]["wall_time"])
            if "failed" in r["result"]["outcome"]:
                failed += 1
                print(f"ray_sweep: cell failed: {r['result']['outcome']['failed']['reason']}",
                      file=sys.stderr)
        if refused:
            for ref in pending:
                ray.cancel(ref, force=True)
            print(f"ray_sweep: {refused}", file=sys.stderr)
            sys.exit(3)
        now = time.monotonic()
        if not a.quiet and (now - last_print > 5.0 or not pending):
            last_print = now
            running = min(len(pending), cpus)
            remaining = len(pending) - running
            eta = (f"{len(pending) * sum(task_times) / len(task_times) / cpus:.0f} s"
                   if task_times else "?")
            print(f"ray_sweep: {done} done ({failed} failed), {running} running, {remaining} "
                  f"waiting, {now - t_ready:.0f} s, ETA {eta}", file=sys.stderr)
    # One line per driver run: the cluster, and the time spent in tasks outside the cells'
    # own searches (starting the subprocess, the build check).
    info.update({"done": done, "failed": failed, "lost": lost, "wall": time.monotonic() - t_ready,
                 "task_time": sum(task_times), "in_task_overhead": sum(overheads)})
    with open(a.cluster_info, "a") as f:
        f.write(json.dumps(info) + "\n")
    ray.shutdown()
    if lost:
        print(f"ray_sweep: {lost} cells lost (their nodes kept dying); run again to redo them",
              file=sys.stderr)
        sys.exit(4)


if __name__ == "__main__":
    main()
