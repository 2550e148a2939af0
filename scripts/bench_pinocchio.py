#!/usr/bin/env python3
"""RNEA, CRBA and ABA: upc against Pinocchio (C++, -O3) on the same URDFs, side by side.

Pinocchio comes from PyPI (`pin`, installed by scripts/setup.sh in the robot venv); its C++
headers and libraries are in the wheel, and scripts/bench_pinocchio.cpp is compiled against
them once (about 2 minutes; cached under ~/.cache/upc/pinbench). upc's side is its criterion
bench (`UPC_BENCH_URDF=… cargo bench --bench dynamics`). Both cycle through 64 random states
drawn the same way (q within the joint limits, the free-flyer within ±1 m and any orientation;
v, a in [-1, 1]; free-flyer root).

Like with like: upc's `crba` leaves the world placements, the world joint Jacobian and M(q) with
both triangles; it is compared with Pinocchio's `crba(…, Convention::WORLD)` plus the copy of
M's upper triangle into the lower one ("crba"). Pinocchio's default, `Convention::LOCAL`, fills
M's upper triangle only and no world quantities ("crba local" row, same upc figure). Pinocchio's
ABA also leaves the joint forces, which upc's does not compute. Pinocchio is compiled with
-march=native; upc is built for the baseline x86-64 target (SSE2).

On a shared machine a run's mean or median moves by ±20 %: both sides report the per-call time
of their fastest batch (Pinocchio: 50 batches of 200 calls; upc: criterion's 50 samples), and
each side is run --repeat times, alternating, keeping the fastest.

    ~/.cache/upc/robot-venv/bin/python scripts/bench_pinocchio.py            # default URDFs
    ~/.cache/upc/robot-venv/bin/python scripts/bench_pinocchio.py my.urdf    # yours
    ~/.cache/upc/robot-venv/bin/python scripts/bench_pinocchio.py --repeat 1 # quicker
"""

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys

import pinocchio as pin

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CACHE = os.path.expanduser("~/.cache/upc/pinbench")
# The wheel's prefix: headers, libraries and example-robot-data's share/.
PREFIX = pin.__file__[: pin.__file__.index("cmeel.prefix") + len("cmeel.prefix")]


def default_urdfs():
    import icub_models

    erd = os.path.join(PREFIX, "share", "example-robot-data", "robots")
    return [
        os.path.join(ROOT, "assets", "icub_like", "icub_like.urdf"),
        str(icub_models.get_model_file("iCubGazeboV2_5")),
        os.path.join(erd, "romeo_description", "urdf", "romeo.urdf"),
        os.path.join(erd, "tiago_description", "robots", "tiago_dual.urdf"),
    ]


def pinocchio_bench():
    src = os.path.join(ROOT, "scripts", "bench_pinocchio.cpp")
    # The definitions Pinocchio's own CMake config exports to its users.
    flags = [
        "-O3", "-march=native", "-DNDEBUG", "-std=c++17", "-Wno-deprecated-declarations",
        "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
        "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
    ]
    digest = hashlib.sha256(open(src, "rb").read() + " ".join(flags).encode()).hexdigest()[:12]
    exe = os.path.join(CACHE, f"bench-{digest}")
    if os.path.exists(exe):
        return exe
    if not os.path.isdir("/usr/include/eigen3"):
        sys.exit("Eigen's headers are missing (/usr/include/eigen3): run scripts/setup.sh")
    os.makedirs(CACHE, exist_ok=True)
    print("compiling the Pinocchio benchmark (about 2 minutes, once)...", file=sys.stderr)
    cmd = ["g++", *flags, src, "-I" + os.path.join(PREFIX, "include"), "-I/usr/include/eigen3",
           "-L" + os.path.join(PREFIX, "lib"), "-lpinocchio_default", "-lboost_serialization",
           "-lboost_filesystem", "-Wl,-rpath," + os.path.join(PREFIX, "lib"), "-o", exe]
    subprocess.run(cmd, check=True)
    return exe


def pinocchio_times(exe, urdf):
    model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
    path = os.path.join(CACHE, hashlib.sha256(urdf.encode()).hexdigest()[:12] + ".bin")
    model.saveToBinary(path)
    return json.loads(subprocess.run([exe, path], check=True, capture_output=True, text=True).stdout)


def upc_times(urdf):
    env = dict(os.environ, UPC_BENCH_URDF=urdf)
    out = subprocess.run(
        ["cargo", "bench", "--bench", "dynamics", "--", "env_urdf/(rnea|crba|aba)$"],
        cwd=ROOT, env=env, capture_output=True, text=True, check=True,
    )
    text = out.stdout + out.stderr
    # The fastest criterion sample (per-iteration time), as Pinocchio's fastest batch.
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    times = {}
    for alg in ("rnea", "crba", "aba"):
        if not re.search(rf"env_urdf/{alg}\s+time:", text):
            continue
        path = os.path.join(target, "criterion", "env_urdf", alg, "new", "sample.json")
        with open(path) as f:
            sample = json.load(f)
        times[alg] = min(t / i for t, i in zip(sample["times"], sample["iters"])) * 1e-3
    skipped = re.search(r"ABA skipped: (.*)", text)
    return times, skipped.group(1) if skipped else None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("urdf", nargs="*", help="URDFs (free-flyer root); default: four robots")
    parser.add_argument("--repeat", type=int, default=2, help="runs of each side (fastest kept)")
    args = parser.parse_args()
    urdfs = args.urdf or default_urdfs()
    exe = pinocchio_bench()
    print(f"{'URDF':<28} {'nv':>4}  {'algorithm':<10} {'upc µs':>8} {'Pinocchio µs':>13} {'ratio':>6}")
    for urdf in urdfs:
        name = os.path.basename(os.path.dirname(urdf)) if urdf.endswith("model.urdf") else os.path.basename(urdf)
        p, u = {}, {}
        for _ in range(max(args.repeat, 1)):
            pr = pinocchio_times(exe, urdf)
            p = {k: min(v, p[k]) if isinstance(v, float) and k in p else v for k, v in pr.items()}
            ur, skipped = upc_times(urdf)
            u = {k: min(v, u.get(k, v)) for k, v in ur.items()}
        for alg, ualg in (("rnea", "rnea"), ("crba", "crba"), ("crba_local", "crba"), ("aba", "aba")):
            label = alg.replace("_", " ")
            note = ""
            if alg == "aba" and not p["aba_finite"]:
                note = "  (Pinocchio returns NaN: M(q) is singular)"
            if ualg in u:
                ratio = u[ualg] / p[alg]
                print(f"{name:<28} {p['nv']:>4}  {label:<10} {u[ualg]:>8.2f} {p[alg]:>13.2f} {ratio:>6.2f}{note}")
            else:
                print(f"{name:<28} {p['nv']:>4}  {label:<10} {'-':>8} {p[alg]:>13.2f}   (upc: {skipped}){note}")


if __name__ == "__main__":
    main()
