#!/usr/bin/env bash
# Runs every test: formatting and lints, Rust unit/integration/doc tests (they run the real
# binaries on generated fixtures), and the Python interop tests that read our tables with
# deltalake/pyarrow/polars, the object-storage tests (SeaweedFS, Ray), and the LeRobot
# interop tests that run LeRobot 0.6.1 itself.
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
echo "== object storage and Ray"
# Every stage against s3:// on a real S3 server (SeaweedFS on 127.0.0.1, started and stopped
# by the tests), concurrent writers, a crash, a wrong secret, deltalake/Ray reading from S3,
# the Ray launcher retrying a killed worker.
RAY_USAGE_STATS_ENABLED=0 AWS_EC2_METADATA_DISABLED=true MILV_BIN="$PWD/target/debug" \
  .venv/bin/python -m pytest tests/s3 -q -p no:cacheprovider
echo "== lerobot interop"
# LeRobot 0.6.1 itself reads what milv-export writes and writes what milv-ingest imports
# (its own venv: Python >= 3.12; tools/setup.sh skips it only when no such Python exists).
if [ -x .venv-lerobot/bin/python ]; then
  MILV_BIN="$PWD/target/debug" .venv-lerobot/bin/python -m pytest tests/lerobot -q -p no:cacheprovider
else
  echo "skipped: no .venv-lerobot (tools/setup.sh found no Python >= 3.12)"
fi
