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
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BINARIES = ("milv-ingest", "milv-ds", "milv-score", "milv-align")


def _has_bins(d: Path) -> bool:
    return all((d / b).is_file() and os.access(d / b, os.X_OK) for b in BINARIES)


@pytest.fixture(scope="session")
def milv_bin() -> Path:
    env = os.environ.get("MILV_BIN")
    if env:
        d = Path(env).resolve()
        if not _has_bins(d):
            pytest.fail(f"MILV_BIN={env}: {', '.join(BINARIES)} not found there (build them first)")
        return d
    for cand in (REPO / "target" / "debug", REPO / "target" / "release"):
        if _has_bins(cand):
            return cand
    pytest.skip("milv-ingest/milv-ds not built and MILV_BIN unset")


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
