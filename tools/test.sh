#!/usr/bin/env bash
# Runs every test: formatting and lints, Rust unit/integration/doc tests (they run the real
# binaries on generated fixtures), and the Python interop tests that read our tables with
# deltalake/pyarrow/polars.
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
