#!/usr/bin/env bash
# Installs what upc needs on a fresh Debian machine (idempotent). The Rust toolchain is assumed
# present (rustup); system packages and the Python environment of the examples are set up here
# and nowhere else.
set -euo pipefail
cd "$(dirname "$0")/.."
need=()
command -v cc >/dev/null 2>&1 || need+=(gcc)
command -v python3 >/dev/null 2>&1 || need+=(python3)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || need+=(python3-venv)
# Eigen's headers: scripts/bench_pinocchio.py compiles Pinocchio's C++ against them.
[ -d /usr/include/eigen3 ] || need+=(libeigen3-dev)
# The lab's certificates for the bridge's TLS (scripts/lab-pki.sh; `upc run --forecaster-over-zenoh`).
command -v openssl >/dev/null 2>&1 || need+=(openssl)
# The font of the PNG figures of `upc compare` (loaded at run time; SVGs do without it).
[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need+=(fonts-dejavu-core)
# CycloneDDS 0.10.2, the C library (headers for the binding's build) that scripts/g1_bus_peer.py
# plays a G1's low-level bus with against upc's rustdds participant; Python's headers to build
# that binding's C extension (see below).
[ -f /usr/include/dds/dds.h ] || need+=(cyclonedds-dev)
python3 -c 'import os, sys, sysconfig
sys.exit(not os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' \
  >/dev/null 2>&1 || need+=(python3-dev)
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}"
fi
command -v cargo >/dev/null 2>&1 || { echo "cargo not found: install Rust (rustup) first" >&2; exit 1; }
# Python environment of the Python participants (examples/python's forecasters) and of MuJoCo:
# iceoryx2's bindings and Zenoh's, the same versions as the Rust crates; MuJoCo, whose wheel
# carries the C library and headers that build.rs links for `upc sim --plant mujoco` (so this
# runs before cargo); rerun's viewer (`upc run --viewer`), the version of the Rust SDK.
if ! .venv/bin/python -c 'import iceoryx2, mujoco, zenoh, rerun' >/dev/null 2>&1; then
  [ -x .venv/bin/python ] || python3 -m venv .venv
  .venv/bin/pip install -q --disable-pip-version-check "iceoryx2==0.10.0" "mujoco==4.0.0" \
    "eclipse-zenoh==1.10.2" "rerun-sdk==0.36.3"
fi
# Ray, the engine of `upc capability` / `upc robustness --engine ray` (scripts/ray_sweep.py is
# the driver; a lab's cluster runs the same version on every node: docs/sweeps.md).
if ! .venv/bin/python -c 'import sys, importlib.metadata
sys.exit(importlib.metadata.version("ray") != "2.52.1")' >/dev/null 2>&1; then
  .venv/bin/pip install -q --disable-pip-version-check "ray==2.52.1"
fi
# Real robots' URDFs and Pinocchio, for the loader tests and scripts/pin_check.py (about 1 GB,
# kept outside the clone so that fresh clones on one machine share it). Not needed to run upc:
# outside CI a failed install only skips those tests, each saying so; under CI (CI=true) it
# fails here, as those tests would.
ROBOT_VENV="${UPC_ROBOT_VENV:-$HOME/.cache/upc/robot-venv}"
if ! "$ROBOT_VENV/bin/python" -c 'import pinocchio, icub_models' >/dev/null 2>&1; then
  if ! { python3 -m venv "$ROBOT_VENV" \
      && "$ROBOT_VENV/bin/pip" install -q --disable-pip-version-check \
           "pin==4.1.0" "example-robot-data==6.0.0" "icub-models==3.2.0"; }; then
    case "${CI:-}" in
      ""|0|false) echo "setup.sh: robot models not installed in $ROBOT_VENV (their tests will be skipped)" >&2 ;;
      *) echo "setup.sh: robot models could not be installed in $ROBOT_VENV, and CI runs their tests" >&2; exit 1 ;;
    esac
  fi
fi
# CycloneDDS's Python binding, 0.10.2 like Debian's library, in the robot venv: the other side of
# the wire for the DDS bus tests (scripts/g1_bus_peer.py, an independent G1 low-level bus). Built
# from the sdist against Debian's libddsc, never a wheel: wheels bundle their own libddsc, and a
# Cyclone of another version (0.11) crashes a 0.10.2 peer. The build looks for include/, lib/ and
# bin/ under CYCLONEDDS_HOME, so one of symlinks to Debian's files is made for it. Some seconds
# (a C extension). Outside CI a failed install only skips those tests; under CI it fails here.
if ! "$ROBOT_VENV/bin/python" -c 'import sys, importlib.metadata, cyclonedds.core
sys.exit(importlib.metadata.version("cyclonedds") != "0.10.2")' >/dev/null 2>&1; then
  cyclone_home="$HOME/.cache/upc/cyclonedds-home"
  multiarch="$(dpkg-architecture -qDEB_HOST_MULTIARCH 2>/dev/null || gcc -print-multiarch)"
  if ! { [ -n "$multiarch" ] && [ -f "/usr/lib/$multiarch/libddsc.so" ] \
      && mkdir -p "$cyclone_home/include" "$cyclone_home/lib" "$cyclone_home/bin" \
      && for d in dds ddsc idl idlc; do ln -sfn "/usr/include/$d" "$cyclone_home/include/$d"; done \
      && for l in libddsc.so libcycloneddsidl.so; do
           ln -sfn "/usr/lib/$multiarch/$l" "$cyclone_home/lib/$l"; done \
      && ln -sfn /usr/bin/idlc "$cyclone_home/bin/idlc" \
      && CYCLONEDDS_HOME="$cyclone_home" "$ROBOT_VENV/bin/pip" install -q \
           --disable-pip-version-check --no-binary cyclonedds "cyclonedds==0.10.2" \
      && "$ROBOT_VENV/bin/python" -c 'import sys, importlib.metadata, cyclonedds.core
sys.exit(importlib.metadata.version("cyclonedds") != "0.10.2")'; }; then
    case "${CI:-}" in
      ""|0|false) echo "setup.sh: CycloneDDS 0.10.2 not installed in $ROBOT_VENV (the DDS bus tests will be skipped)" >&2 ;;
      *) echo "setup.sh: CycloneDDS 0.10.2 could not be installed in $ROBOT_VENV, and CI runs the DDS bus tests" >&2; exit 1 ;;
    esac
  fi
fi
