"""Fixtures for the LeRobot interop tests: MILV's LeRobot import/export checked with LeRobot 0.6.1 itself.

Run with the LeRobot venv (tools/setup.sh makes it; lerobot needs Python >= 3.12):

    MILV_BIN=target/debug .venv-lerobot/bin/python -m pytest tests/lerobot -q -p no:cacheprovider

Environment:
  MILV_BIN  folder holding the built `milv-ingest`, `milv-ds` and `milv-export`
            (default: target/debug, then target/release, if they exist there).
            If MILV_BIN is set and a binary is missing, the tests fail; if it is unset
            and no build is found, they are skipped.

Everything runs offline: HF_HUB_OFFLINE / HF_DATASETS_OFFLINE are set, and HF_HOME,
HF_LEROBOT_HOME and HF_DATASETS_CACHE point into a temporary folder (set here, before
lerobot or datasets are imported; HF_DATASETS_CACHE is moved per test as well), so a
LeRobotDataset that would fall back to the Hub fails fast instead of downloading.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BINARIES = ("milv-ingest", "milv-ds", "milv-export")

_HF_TMP = Path(tempfile.mkdtemp(prefix="milv-lerobot-hf-"))
os.environ.update(
    HF_HUB_OFFLINE="1",
    HF_DATASETS_OFFLINE="1",
    HF_HUB_DISABLE_TELEMETRY="1",
    HF_HOME=str(_HF_TMP / "home"),
    HF_LEROBOT_HOME=str(_HF_TMP / "lerobot"),
    HF_DATASETS_CACHE=str(_HF_TMP / "datasets"),
    TOKENIZERS_PARALLELISM="false",
)
sys.path.insert(0, str(REPO / "tools" / "lerobot"))
sys.path.insert(0, str(REPO / "tests" / "pyutil"))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def pytest_unconfigure(config):
    shutil.rmtree(_HF_TMP, ignore_errors=True)


@pytest.fixture(autouse=True)
def _per_test_datasets_cache(tmp_path, monkeypatch):
    """Each test's Arrow cache (datasets' from_parquet) lives in its own temp dir."""
    cache = tmp_path / "hf-datasets-cache"
    monkeypatch.setenv("HF_DATASETS_CACHE", str(cache))
    import datasets.config

    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", cache)


@pytest.fixture(scope="session")
def milv_bin() -> Path:
    import milvtest

    return milvtest.find_milv_bin(BINARIES)


# --------------------------------------------------------------------------
# LeRobot datasets written by LeRobot itself (tools/lerobot/write_dataset.py)

CAMERAS = ["observation.images.top", "observation.images.wrist"]


@pytest.fixture(scope="session")
def lerobot_video(tmp_path_factory):
    """3 episodes (12, 15, 18 frames), 64x64, 10 fps, two AV1 cameras."""
    import lrutil

    return lrutil.write_lerobot(tmp_path_factory.mktemp("lr") / "lr_video", cameras=CAMERAS, images=False)


@pytest.fixture(scope="session")
def lerobot_images(tmp_path_factory):
    """The same content with inline PNG images (use_videos=False)."""
    import lrutil

    return lrutil.write_lerobot(tmp_path_factory.mktemp("lr") / "lr_images", cameras=CAMERAS, images=True)


# --------------------------------------------------------------------------
# A MILV dataset made without LeRobot: frame folders + milv-sidecar/1 JSON


@pytest.fixture(scope="session")
def milv_source(milv_bin, tmp_path_factory):
    import lrutil

    return lrutil.make_milv_dataset(milv_bin, tmp_path_factory.mktemp("milv"))
