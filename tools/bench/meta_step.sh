#!/usr/bin/env bash
# The second-order meta step: milv-train against the same step in PyTorch eager, same threads,
# one run. Installs torch's full Python dependencies into .venv on first use (the build
# needs only libtorch). Usage: tools/bench/meta_step.sh [--input latent|image] [--size 128] [--threads 2] ...
set -euo pipefail
cd "$(dirname "$0")/../.."
MILV_SKIP_BUILD=1 tools/setup.sh
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  .venv/bin/pip install -q --disable-pip-version-check -r tools/bench/requirements-torch-full.txt
fi
cargo build --locked --release -p milv-train --bin milv-train --quiet
exec .venv/bin/python tools/bench/meta_step.py --milv-train target/release/milv-train "$@"
