"""The scores and curated tables, read with the ecosystem's own readers.

Ingests the bundled samples, runs `milv-score run` and `milv-score curate`, then reads
the tables with deltalake, polars and pyarrow, and recomputes every frame's beta of the
recorded frames from the stored PNG/JPEG bytes with scikit-image 0.26 and numpy (an
independent implementation of spec/quality.md): they must agree to 1e-6.
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from PIL import Image
from skimage.metrics import structural_similarity

READER = Path(__file__).with_name("delta_reader.py")
TIMEOUT = 600


def run_json(args, ok=(0,)):
    p = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=TIMEOUT)
    if p.returncode not in ok:
        pytest.fail(f"{args} exited {p.returncode}\n{p.stdout}\n{p.stderr}")
    return json.loads(p.stdout)


def read(work: Path, path: Path, reader: str, dump_dir=None) -> dict:
    req = work / f"req-{reader}-{path.name}.json"
    req.write_text(json.dumps({"reads": [{"path": str(path), "version": None, "reader": reader,
                                          "dump": True, "dump_dir": str(dump_dir) if dump_dir else None}]}))
    p = subprocess.run([sys.executable, str(READER), str(req)], capture_output=True, text=True, timeout=TIMEOUT)
    answer = json.loads(p.stdout)
    assert "error" not in answer, answer.get("error")
    return answer["results"][0]


def luma(rgb: np.ndarray) -> np.ndarray:
    f = rgb.astype(np.float64)
    return 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]


def brenner(y: np.ndarray) -> float:
    h, w = y.shape
    sh = ((y[:, 2:] - y[:, :-2]) ** 2).sum()
    sv = ((y[2:, :] - y[:-2, :]) ** 2).sum()
    return (sh + sv) / ((h * (w - 2) + (h - 2) * w) * 255.0**2)


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    return structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                 data_range=255)


@pytest.fixture(scope="module")
def scored(milv_bin: Path, samples_dir: Path, tmp_path_factory):
    score = milv_bin / "milv-score"
    work = tmp_path_factory.mktemp("scores")
    ds = work / "ds"
    run_json([milv_bin / "milv-ingest", ds, "--manifest", samples_dir / "manifest.jsonl", "--json"])
    run = run_json([score, "run", ds, "--json"])
    cur = run_json([score, "curate", ds, "--top-fraction", "0.75", "--min-episode-fraction", "0", "--json"])
    frames = read(work, ds / "frames", "deltalake", work / "frames")
    return dict(work=work, ds=ds, run=run, cur=cur, frames=frames,
                scores=read(work, ds / "scores", "deltalake"),
                scores_pl=read(work, ds / "scores", "polars"),
                curated=read(work, ds / "curated", "deltalake"),
                episodes=read(work, ds / "episodes", "deltalake"))


def test_scores_schema_and_counts(scored):
    s, pl = scored["scores"], scored["scores_pl"]
    assert s["num_rows"] == scored["frames"]["num_rows"] == scored["run"]["frames_scored"]
    assert pl["num_rows"] == s["num_rows"]
    want = {"episode_id": "string", "frame_index": "int32", "source_table": "string", "model_id": "string",
            "run_id": "string", "brenner_raw": "double", "brenner": "double", "ssim": "double",
            "beta": "double", "weight": "double"}
    assert {k: v["type"] for k, v in s["columns"].items()} == want
    assert {r["run_id"] for r in s["rows"]} == {scored["run"]["run_id"]}


def test_normalisation_parameters_in_file_metadata(scored):
    files = list((scored["ds"] / "scores").glob("*.parquet"))
    assert files
    for f in files:
        meta = pq.read_metadata(f).metadata
        params = json.loads(meta[b"milv.scores"])
        assert params["run_id"] == scored["run"]["run_id"]
        assert params["brenner_min"] == pytest.approx(scored["run"]["brenner_min"], abs=0)
        assert params["brenner_max"] == pytest.approx(scored["run"]["brenner_max"], abs=0)


def test_beta_matches_an_independent_implementation(scored):
    eps = {e["episode_id"]: e for e in scored["episodes"]["rows"]}
    by_ep: dict[str, list] = {}
    for r in scored["frames"]["rows"]:
        by_ep.setdefault(r["episode_id"], []).append(r)
    got = {(r["episode_id"], r["frame_index"]): r for r in scored["scores"]["rows"]}
    bmin, bmax = scored["run"]["brenner_min"], scored["run"]["brenner_max"]
    checked = 0
    for eid, rows in by_ep.items():
        e = eps[eid]
        imgs = []
        for r in sorted(rows, key=lambda r: r["frame_index"]):
            data = Path(r["image_file"]).read_bytes()
            if e["frame_encoding"] == "raw":
                imgs.append(np.frombuffer(data, np.uint8).reshape(e["height"], e["width"], 3))
            else:
                imgs.append(np.asarray(Image.open(io.BytesIO(data)).convert("RGB")))
        ys = [luma(i) for i in imgs]
        pairs = [ssim(ys[t], ys[t + 1]) for t in range(len(ys) - 1)]
        for t, y in enumerate(ys):
            s = pairs[min(t, len(pairs) - 1)]
            b = brenner(y)
            row = got[(eid, t)]
            assert row["brenner"] == pytest.approx(b, abs=1e-9)
            assert row["ssim"] == pytest.approx(s, abs=1e-6)
            assert row["beta"] == pytest.approx(b * (s + 1) / 2, abs=1e-6)
            w = (b - bmin) / (bmax - bmin) * (s + 1) / 2
            assert row["weight"] == pytest.approx(w, abs=1e-6)
            checked += 1
    assert checked == scored["scores"]["num_rows"]


def test_curated_view(scored):
    cur, rows = scored["cur"], scored["curated"]["rows"]
    assert len(rows) == cur["frames_kept"]
    assert all(r["weight"] >= cur["threshold"] for r in rows)
    assert cur["frames_kept"] >= 0.75 * cur["frames_scored"]
    weights = {(r["episode_id"], r["frame_index"]): r["weight"] for r in scored["scores"]["rows"]}
    for r in rows:
        assert r["weight"] == pytest.approx(weights[(r["episode_id"], r["frame_index"])], abs=1e-12)
