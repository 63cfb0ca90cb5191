"""Helpers shared by the Python test suites (tests/interop, tests/lerobot): finding the
built MILV binaries and running them with a clear failure message."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def has_bins(d: Path, binaries) -> bool:
    return all((d / b).is_file() and os.access(d / b, os.X_OK) for b in binaries)


def find_milv_bin(binaries) -> Path:
    """$MILV_BIN (failing if the binaries are missing there), else target/debug or
    target/release; skips the tests when nothing is built and MILV_BIN is unset."""
    env = os.environ.get("MILV_BIN")
    if env:
        d = Path(env).resolve()
        if not has_bins(d, binaries):
            missing = [b for b in binaries if not (d / b).is_file()]
            pytest.fail(f"MILV_BIN={env}: {', '.join(missing)} not found there (build them first)")
        return d
    for cand in (REPO / "target" / "debug", REPO / "target" / "release"):
        if has_bins(cand, binaries):
            return cand
    pytest.skip(f"{'/'.join(binaries)} not built and MILV_BIN unset")


def run_checked(args, ok_codes=(0,), timeout=300) -> subprocess.CompletedProcess:
    """Runs a command; fails the test with its output unless it exits with an ok code
    (`ok_codes=None`: any code)."""
    args = [str(a) for a in args]
    p = subprocess.run(args, capture_output=True, text=True, timeout=timeout)
    if ok_codes is not None and p.returncode not in ok_codes:
        pytest.fail(f"{' '.join(args)} exited {p.returncode}\n--- stdout\n{p.stdout}\n--- stderr\n{p.stderr}")
    return p


def run_json(args, ok_codes=(0,), timeout=300):
    p = run_checked(args, ok_codes, timeout)
    try:
        return json.loads(p.stdout)
    except json.JSONDecodeError as e:
        pytest.fail(f"{' '.join(map(str, args))}: stdout is not one JSON document ({e})\n{p.stdout}\n{p.stderr}")
