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
