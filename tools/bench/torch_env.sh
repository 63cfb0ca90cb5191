# Sourced (from the repository root) by the benchmarks that time milv-train beside PyTorch
# eager: installs torch's full Python dependencies into .venv on first use (the build
# needs only libtorch) and builds milv-train in release.
MILV_SKIP_BUILD=1 tools/setup.sh
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  .venv/bin/pip install -q --disable-pip-version-check -r tools/bench/requirements-torch-full.txt
fi
cargo build --locked --release -p milv-train --bin milv-train --quiet
