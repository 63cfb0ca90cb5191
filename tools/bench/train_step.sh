#!/usr/bin/env bash
# The A-CycleGAN step: milv-train against the same step in PyTorch eager, same threads,
# one run. Installs torch's full Python dependencies into .venv on first use (the build
# needs only libtorch). Usage: tools/bench/train_step.sh [--size 128] [--threads 2] ...
set -euo pipefail
cd "$(dirname "$0")/../.."
. tools/bench/torch_env.sh
exec .venv/bin/python tools/bench/train_step.py --milv-train target/release/milv-train "$@"
