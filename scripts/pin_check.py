#!/usr/bin/env python3
"""Cross-check upc's dynamics against Pinocchio on real robots' URDFs.

For every URDF given (or, with --packages, every URDF shipped by the PyPI packages
`example-robot-data` and `icub-models`), at random configurations and velocities: M(q),
h(q, v) (RNEA with gravity), the CoM and the LOCAL_WORLD_ALIGNED Jacobian of a few link frames,
from `upc model --json` and from Pinocchio (`pin`), joints matched by name. Prints one line per
URDF and the worst disagreement per quantity; exits 1 if a URDF Pinocchio loads is refused by
upc or a disagreement exceeds --tol (absolute, on quantities scaled to order one by the robot's
mass).

    scripts/setup.sh   # installs pin, example-robot-data, icub-models (see UPC_ROBOT_VENV)
    ~/.cache/upc/robot-venv/bin/python scripts/pin_check.py --packages --upc target/release/upc
"""

import argparse
import glob
import json
import math
import os
import re
import subprocess
import sys

import numpy as np
import pinocchio as pin


def package_urdfs():
    # example-robot-data installs its robots under cmeel.prefix (no importable module).
    import icub_models

    site = os.path.dirname(os.path.dirname(icub_models.__file__))
    erd = os.path.join(site, "cmeel.prefix", "share", "example-robot-data", "robots")
    if not os.path.isdir(erd):
        sys.exit(f"example-robot-data is not installed (no {erd})")
    out = sorted(glob.glob(os.path.join(erd, "**", "*.urdf"), recursive=True))
    out += sorted(str(icub_models.get_model_file(n)) for n in icub_models.get_robot_names())
    return out


def upc_json(upc, urdf, q=None, v=None, frame=None):
    cmd = [upc, "model", urdf, "--json"]
    if q is not None:
        cmd += ["--q", ",".join(repr(float(x)) for x in q), "--v", ",".join(repr(float(x)) for x in v)]
    if frame:
        cmd += ["--frame", frame]
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "RUST_LOG": "warn"})
    if r.returncode != 0:
        raise RuntimeError(r.stderr.strip().splitlines()[-1] if r.stderr.strip() else "failed")
    out = json.loads(r.stdout)
    # The inertia repairs upc made (largest change of each, kg·m²): M and h may differ from
    # Pinocchio's, which takes the tensors as they are, by about that much.
    out["repairs"] = [float(m) for m in re.findall(r"largest change ([0-9.eE+-]+) kg", r.stderr)]
    return out


def check(upc, urdf, rng, configs, frames_per):
    ref = upc_json(upc, urdf)
    floating = ref["floating_base"]
    model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer()) if floating else pin.buildModelFromUrdf(urdf)
    data = model.createData()
    names = ref["velocity_names"][6:] if floating else ref["velocity_names"]
    off = 6 if floating else 0
    qoff = 7 if floating else 0
    nv = ref["nv"]
    # Velocity index in Pinocchio of each upc velocity index.
    perm = list(range(off))
    joints = []
    for n in names:
        jid = model.getJointId(n)
        if jid >= model.njoints:
            raise RuntimeError(f"Pinocchio has no joint '{n}'")
        j = model.joints[jid]
        perm.append(j.idx_v)
        joints.append((jid, j))
    mass = sum(i.mass for i in model.inertias)
    scale = max(mass, 1.0)
    # Link frames present in both (BODY frames in Pinocchio), a few spread over the tree.
    links = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    pick = [links[int(k)] for k in np.linspace(0, len(links) - 1, min(frames_per, len(links)))]
    worst = {"M": 0.0, "h": 0.0, "com": 0.0, "J": 0.0}
    # Repaired inertias change M and h entries by at most the repairs' sum (scaled like them).
    allowance = 10 * sum(ref["repairs"]) / scale
    for _ in range(configs):
        qu = np.zeros(ref["nq"])
        qp = pin.neutral(model)
        if floating:
            p = rng.uniform(-1, 1, 3)
            quat = rng.normal(size=4)
            quat /= np.linalg.norm(quat)
            qu[:3], qu[3:7] = p, quat
            qp[:3], qp[3:7] = p, quat
        for k, (jid, j) in enumerate(joints):
            lo, hi = model.lowerPositionLimit[j.idx_q], model.upperPositionLimit[j.idx_q]
            lo = lo if np.isfinite(lo) and lo > -math.pi else -math.pi
            hi = hi if np.isfinite(hi) and hi < math.pi else math.pi
            if j.nq == 2:  # continuous: (cos, sin) in Pinocchio, the angle in upc
                th = rng.uniform(-math.pi, math.pi)
                qp[j.idx_q], qp[j.idx_q + 1] = math.cos(th), math.sin(th)
            else:
                th = rng.uniform(lo, hi) if hi > lo else lo
                qp[j.idx_q] = th
            qu[qoff + k] = th
        vu = rng.normal(size=nv)
        vp = np.zeros(model.nv)
        for k in range(nv):
            vp[perm[k]] = vu[k]
        for f in pick:
            u = upc_json(upc, urdf, qu, vu, f)
            M = pin.crba(model, data, qp)
            M = np.triu(M) + np.triu(M, 1).T
            h = pin.nonLinearEffects(model, data, qp, vp)
            com = pin.centerOfMass(model, data, qp)
            pin.computeJointJacobians(model, data, qp)
            pin.updateFramePlacements(model, data)
            J = pin.getFrameJacobian(model, data, model.getFrameId(f), pin.LOCAL_WORLD_ALIGNED)
            Mu, hu = np.array(u["M"]), np.array(u["h"])
            Ju = np.array(u["frame"]["jacobian_local_world_aligned"])
            worst["M"] = max(worst["M"], np.abs(Mu - M[np.ix_(perm, perm)]).max() / scale)
            worst["h"] = max(worst["h"], np.abs(hu - h[perm]).max() / (scale * 9.81))
            worst["com"] = max(worst["com"], np.abs(np.array(u["com"]) - com).max())
            worst["J"] = max(worst["J"], np.abs(Ju - J[:, perm]).max())
    return worst, allowance


def main():
    a = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    a.add_argument("urdf", nargs="*")
    a.add_argument("--packages", action="store_true", help="every URDF of example-robot-data and icub-models")
    a.add_argument("--upc", default="target/release/upc")
    a.add_argument("--configs", type=int, default=3)
    a.add_argument("--frames", type=int, default=2)
    a.add_argument("--tol", type=float, default=1e-10)
    a.add_argument("--seed", type=int, default=1)
    a.add_argument("--list", action="store_true", help="print the URDF paths and stop")
    a.add_argument(
        "--known-refusal",
        action="append",
        default=[],
        help="file name of a URDF upc refuses on purpose (physically meaningless)",
    )
    args = a.parse_args()
    urdfs = args.urdf + (package_urdfs() if args.packages else [])
    if args.list:
        print("\n".join(urdfs))
        return 0
    rng = np.random.default_rng(args.seed)
    worst = {"M": (0.0, ""), "h": (0.0, ""), "com": (0.0, ""), "J": (0.0, "")}
    loaded = refused = skipped = bad = 0
    for f in urdfs:
        name = os.path.relpath(f, os.path.dirname(os.path.dirname(f)))
        try:
            pin.buildModelFromUrdf(f)
        except Exception as e:  # Pinocchio refuses it too: not upc's to load
            print(f"skip    {name}: Pinocchio refuses it ({str(e).splitlines()[0][:80]})")
            skipped += 1
            continue
        try:
            w, allowance = check(args.upc, f, rng, args.configs, args.frames)
        except RuntimeError as e:
            known = os.path.basename(f) in args.known_refusal
            print(f"{'refused' if known else 'REFUSED'} {name}: {e}")
            refused += not known
            continue
        loaded += 1
        tol = max(args.tol, allowance)
        ok = all(x <= tol for x in w.values())
        bad += not ok
        if allowance <= args.tol:
            for k, x in w.items():
                if x > worst[k][0]:
                    worst[k] = (x, name)
        label = "ok" if ok else "DIFFERS"
        note = f" (inertias repaired: within {allowance:.1e})" if allowance > args.tol else ""
        print(f"{label:7} {name}: " + ", ".join(f"{k} {x:.1e}" for k, x in w.items()) + note)
    print(f"\n{loaded} loaded and compared, {refused} refused by upc, {skipped} refused by Pinocchio too")
    for k, (x, n) in worst.items():
        print(f"worst {k} (URDFs taken as they are): {x:.2e} ({n})")
    print(f"agreeing within {args.tol:g}: {loaded - bad} of {loaded + refused} URDFs upc should load")
    return 0 if refused == 0 and bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
