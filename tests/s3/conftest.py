"""Fixtures of the object-storage tests: a SeaweedFS S3 server per test session
(tools/s3/seaweedfs.py) and a runner for the MILV binaries that keeps every output for the
secret check.

Every MILV process the tests run gets only the standard AWS variables (endpoint, keys,
region, AWS_ALLOW_HTTP) and AWS_EC2_METADATA_DISABLED=true, so nothing ever probes an
address outside the machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tools" / "s3"))
from seaweedfs import BUCKET, SeaweedFS  # noqa: E402

BIN = Path(os.environ.get("MILV_BIN", REPO / "target" / "debug"))


@pytest.fixture(scope="session")
def s3(tmp_path_factory):
    server = SeaweedFS(tmp_path_factory.mktemp("seaweedfs"))
    yield server
    server.stop()


class Runner:
    """Runs MILV binaries against the server, keeping every output for the secret check."""

    def __init__(self, s3: SeaweedFS, cache: Path):
        self.s3 = s3
        self.outputs: list[str] = []
        self.cache = cache

    def run(self, tool: str, *args: str, ok=True, secret: str | None = None, json_out=False, timeout=900):
        argv = [str(BIN / tool), *map(str, args)] + (["--json"] if json_out else [])
        env = self.s3.env(secret)
        env["MILV_INPUT_CACHE"] = str(self.cache)
        p = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=timeout)
        self.outputs += [p.stdout, p.stderr]
        if ok and p.returncode != 0:
            raise AssertionError(f"{' '.join(argv)} exited {p.returncode}\nstdout: {p.stdout[-3000:]}\nstderr: {p.stderr[-3000:]}")
        if json_out and p.returncode == 0:
            return json.loads(p.stdout)
        return p


@pytest.fixture(scope="session")
def milv(s3, tmp_path_factory):
    return Runner(s3, tmp_path_factory.mktemp("input-cache"))
