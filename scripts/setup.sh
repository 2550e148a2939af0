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
# The font of the PNG figures of `upc compare` (loaded at run time; SVGs do without it).
[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need+=(fonts-dejavu-core)
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}"
fi
command -v cargo >/dev/null 2>&1 || { echo "cargo not found: install Rust (rustup) first" >&2; exit 1; }
# Python environment of examples/python (the external forecaster): iceoryx2's bindings, the
# same version as the Rust crate.
if ! .venv/bin/python -c 'import iceoryx2' >/dev/null 2>&1; then
  python3 -m venv .venv
  .venv/bin/pip install -q --disable-pip-version-check "iceoryx2==0.10.0"
fi
