"""Fixtures for the Python interop tests.

Environment:
  MILV_BIN      folder holding the built `milv-ingest`, `milv-ds`, `milv-score` and
                `milv-align` binaries
                (default: target/debug, then target/release, if they exist there)
  MILV_SAMPLES  folder made by tools/make_samples.sh (default: samples/ when it has
                a manifest.jsonl, otherwise the samples are generated into a temp dir)

If MILV_BIN is set and the binaries are missing, the tests fail; if it is unset
and no build is found, they are skipped.

The Delta reads themselves run in a subprocess (delta_reader.py): this pytest
process never imports `deltalake` or `polars`.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "pyutil"))
import milvtest  # noqa: E402
BINARIES = ("milv-ingest", "milv-ds", "milv-score", "milv-align")


@pytest.fixture(scope="session")
def milv_bin() -> Path:
    return milvtest.find_milv_bin(BINARIES)


@pytest.fixture(scope="session")
def samples_dir(tmp_path_factory) -> Path:
    env = os.environ.get("MILV_SAMPLES")
    if env:
        d = Path(env).resolve()
        if not (d / "manifest.jsonl").is_file():
            pytest.fail(f"MILV_SAMPLES={env}: no manifest.jsonl (run tools/make_samples.sh)")
        return d
    if (REPO / "samples" / "manifest.jsonl").is_file():
        return REPO / "samples"
    if shutil.which("ffmpeg") is None:
        pytest.skip("no samples and no ffmpeg to make them")
    d = tmp_path_factory.mktemp("samples")
    subprocess.run(["bash", str(REPO / "tools" / "make_samples.sh"), str(d)], check=True)
    return d
