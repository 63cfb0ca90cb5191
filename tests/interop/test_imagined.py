"""The imagined table written by `milv-train translate`, read with deltalake/pyarrow and
polars: latents decode with numpy to the recorded dtype and shape, frames are PNGs of the
model's size, and every frame has a predicted action."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

READ = textwrap.dedent(
    """
    import io, json, os, sys
    import numpy as np
    import polars as pl
    from deltalake import DeltaTable
    from PIL import Image
    t = DeltaTable(sys.argv[1]).to_pyarrow_table()
    out = {"rows": t.num_rows, "polars_rows": pl.read_delta(sys.argv[1]).height,
           "types": {f.name: str(f.type) for f in t.schema}, "latents": [], "images": [], "actions": []}
    for r in t.to_pylist():
        lat = np.frombuffer(r["latent"], dtype={"f16": np.float16, "f32": np.float32}[r["latent_dtype"]])
        lat = lat.reshape(r["latent_shape"])
        out["latents"].append([list(lat.shape), bool(np.isfinite(lat).all()), float(np.abs(lat).max())])
        out["images"].append(list(Image.open(io.BytesIO(r["image"])).size))
        out["actions"].append(r["action"])
    print(json.dumps(out)); sys.stdout.flush(); os._exit(0)
    """
)


def run_json(args):
    p = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=900)
    if p.returncode != 0:
        pytest.fail(f"{args} exited {p.returncode}\n{p.stdout}\n{p.stderr}")
    return json.loads(p.stdout)


@pytest.fixture(scope="module")
def translated(milv_bin: Path, tmp_path_factory):
    train = milv_bin / "milv-train"
    if not train.is_file():
        if os.environ.get("MILV_BIN"):
            pytest.fail(f"{train} not built")
        pytest.skip("milv-train not built")
    work = tmp_path_factory.mktemp("imagined")
    sim, ds, run = work / "sim", work / "ds", work / "run"
    subprocess.run([milv_bin / "milv-sim", "gen", "--task", "drawing", "--episodes", "2", "--seed", "3",
                    "--size", "32", "--out", sim], check=True, capture_output=True)
    run_json([milv_bin / "milv-ingest", ds, "--manifest", sim / "manifest.jsonl", "--json"])
    run_json([milv_bin / "milv-align", ds, "--features", "state", "--json"])
    run_json([train, "cyclegan", ds, "--out", run, "--tiny", "--size", "32", "--steps", "3",
              "--threads", "1", "--json"])
    rep = run_json([train, "translate", ds, "--checkpoint", run / "checkpoints" / "step-00000003", "--json"])
    p = subprocess.run([sys.executable, "-c", READ, str(ds / "imagined")], capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr
    return rep, json.loads(p.stdout)


def test_every_translated_frame_is_readable(translated):
    rep, t = translated
    assert t["rows"] == t["polars_rows"] == rep["frames"] > 0
    assert t["types"]["latent"] == "binary" and t["types"]["action"].startswith("list<")
    shape = rep["latent_shape"]
    assert all(s == shape and finite for s, finite, _ in t["latents"])
    assert any(m > 0 for _, _, m in t["latents"])
    assert all(size == [32, 32] for size in t["images"])
    assert all(len(a) == 2 and all(v == v for v in a) for a in t["actions"])
