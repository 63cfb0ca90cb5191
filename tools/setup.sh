#!/usr/bin/env bash
# Installs everything MILV needs on a fresh Debian 12 machine, then builds.
# Idempotent: each step checks before it installs. Nothing else is assumed by hand.
set -euo pipefail
cd "$(dirname "$0")/.."

log() { printf '\033[1msetup:\033[0m %s\n' "$*" >&2; }

# System packages: FFmpeg development files (ffmpeg-next), clang (bindgen), the ffmpeg CLI
# (sample generation, benchmarks), GNU time (peak RSS in benchmarks), DejaVu Sans (milv-plot
# chart text, read from /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf), Mesa's EGL and
# OSMesa (headless MuJoCo rendering of the alignment validation set, tools/mujoco).
APT_PACKAGES=(pkg-config clang libclang-dev libavcodec-dev libavformat-dev libavutil-dev
  libswscale-dev libswresample-dev libavfilter-dev libavdevice-dev ffmpeg time python3-venv
  fonts-dejavu-core libegl1 libgl1-mesa-dri libosmesa6)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  log "apt-get install ${missing[*]}"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Python packages for interop tests and benchmarks, pinned, in a project-local venv.
VENV=.venv
if [ ! -x "$VENV/bin/python" ]; then
  log "creating $VENV"
  python3 -m venv "$VENV"
fi
stamp="$VENV/.requirements.sha256"
want=$(sha256sum tools/requirements-torch.txt tools/requirements.txt | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  log "pip install -r tools/requirements.txt"
  "$VENV/bin/pip" install -q --disable-pip-version-check -r tools/requirements.txt
  # libtorch for milv-train (tch): the PyPI wheel without its 3.5 GB of CUDA libraries.
  log "pip install --no-deps -r tools/requirements-torch.txt"
  "$VENV/bin/pip" install -q --disable-pip-version-check --no-deps -r tools/requirements-torch.txt
  echo "$want" > "$stamp"
fi

# tch builds against that libtorch: .cargo/config.toml points LIBTORCH at it.
if [ ! -f "$VENV/lib/python3.11/site-packages/torch/lib/libtorch_cpu.so" ]; then
  echo "setup: libtorch missing from $VENV (python3.11 and tools/requirements-torch.txt expected)" >&2
  exit 1
fi

# LeRobot 0.6.1 for the LeRobot interop tests (tests/lerobot) and tools/bench/lerobot.py: its own
# venv, because lerobot needs Python >= 3.12 and torch < 2.12 (the main venv is 3.11 + torch 2.13).
# --no-deps from a fully pinned list that leaves out the CUDA wheels torch does not need to load.
find_python312() {
  local c v
  for c in /root/.pyenv/versions/3.12.1/bin/python python3.12 python3.13 python3.14 \
      "$HOME"/.pyenv/versions/3.1[2-9]*/bin/python python3; do
    v=$(command -v "$c" 2>/dev/null) || continue
    "$v" -c 'import sys, venv; sys.exit(sys.version_info < (3, 12))' 2>/dev/null && { echo "$v"; return 0; }
  done
  return 1
}
LR_VENV=.venv-lerobot
if LR_PY=$(find_python312); then
  lr_stamp="$LR_VENV/.requirements.sha256"
  lr_want=$( { sha256sum tools/requirements-lerobot.txt; "$LR_PY" -V; } | sha256sum | cut -d' ' -f1)
  if [ "$(cat "$lr_stamp" 2>/dev/null)" != "$lr_want" ]; then
    rm -rf "$LR_VENV"
    log "creating $LR_VENV with $LR_PY ($("$LR_PY" -V 2>&1))"
    "$LR_PY" -m venv "$LR_VENV"
    log "pip install --no-deps -r tools/requirements-lerobot.txt (4.5 GB installed)"
    "$LR_VENV/bin/pip" install -q --disable-pip-version-check --no-deps -r tools/requirements-lerobot.txt
    HF_HUB_OFFLINE=1 "$LR_VENV/bin/python" -c 'import torch, lerobot.datasets.lerobot_dataset, deltalake, pytest' \
      || { echo "setup: $LR_VENV: lerobot does not import" >&2; exit 1; }
    echo "$lr_want" > "$lr_stamp"
  fi
else
  log "skipping $LR_VENV: no Python >= 3.12 found (lerobot 0.6.1 needs it); tests/lerobot will not run"
fi

# Rust: the one toolchain on the machine; Cargo.lock pins every crate.
if ! command -v cargo >/dev/null; then
  echo "setup: cargo not found (install Rust 1.95 with rustup)" >&2
  exit 1
fi
if [ "${MILV_SKIP_BUILD:-0}" != 1 ]; then
  log "cargo build --workspace --all-targets"
  cargo build --locked --workspace --all-targets --quiet
fi
