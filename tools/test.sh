#!/usr/bin/env bash
# Runs every test: formatting and lints, Rust unit/integration/doc tests (they run the real
# binaries on generated fixtures), and the Python interop tests that read our tables with
# deltalake/pyarrow/polars, and the LeRobot interop tests that run LeRobot 0.6.1 itself.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup.sh

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
cargo clippy --locked --workspace --all-targets --quiet -- -D warnings
echo "== cargo test"
cargo test --locked --workspace --quiet 2>&1 | tee target/cargo-test.log
echo "== python interop"
fixtures=target/test-fixtures
mkdir -p "$fixtures"
tools/make_samples.sh "$fixtures/samples" >/dev/null
MILV_BIN="$PWD/target/debug" MILV_SAMPLES="$PWD/$fixtures/samples" \
  .venv/bin/python -m pytest tests/interop -q -p no:cacheprovider
echo "== lerobot interop"
# LeRobot 0.6.1 itself reads what milv-export writes and writes what milv-ingest imports
# (its own venv: Python >= 3.12; tools/setup.sh skips it only when no such Python exists).
if [ -x .venv-lerobot/bin/python ]; then
  MILV_BIN="$PWD/target/debug" .venv-lerobot/bin/python -m pytest tests/lerobot -q -p no:cacheprovider
else
  echo "skipped: no .venv-lerobot (tools/setup.sh found no Python >= 3.12)"
fi
