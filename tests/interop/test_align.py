"""The alignments table, read with deltalake and polars, checked against milv-sim's
ground-truth warps of the bundled simulated pairs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SIM = REPO / "samples" / "sim" / "drawing"
READER = Path(__file__).with_name("delta_reader.py")


def run_json(args):
    p = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=600)
    if p.returncode != 0:
        pytest.fail(f"{args} exited {p.returncode}\n{p.stdout}\n{p.stderr}")
    return json.loads(p.stdout)


def read(work: Path, path: Path, reader: str) -> dict:
    req = work / f"req-{reader}.json"
    req.write_text(json.dumps({"reads": [{"path": str(path), "version": None, "reader": reader, "dump": True}]}))
    p = subprocess.run([sys.executable, str(READER), str(req)], capture_output=True, text=True, timeout=600)
    answer = json.loads(p.stdout)
    assert "error" not in answer, answer.get("error")
    return answer["results"][0]


@pytest.fixture(scope="module")
def aligned(milv_bin: Path, tmp_path_factory):
    if not (SIM / "warps.jsonl").is_file():
        pytest.skip("samples/sim/drawing not present")
    work = tmp_path_factory.mktemp("align")
    ds = work / "ds"
    run_json([milv_bin / "milv-ingest", ds, "--manifest", SIM / "manifest.jsonl", "--json"])
    rep = run_json([milv_bin / "milv-align", ds, "--features", "state", "--truth", SIM / "warps.jsonl", "--json"])
    return dict(rep=rep, dl=read(work, ds / "alignments", "deltalake"), pl=read(work, ds / "alignments", "polars"))


def test_schema_and_rows(aligned):
    dl, pl, rep = aligned["dl"], aligned["pl"], aligned["rep"]
    assert dl["num_rows"] == pl["num_rows"] == rep["rows"]
    assert {k: v["type"] for k, v in dl["columns"].items()} == {
        "pair_id": "string", "human_episode_id": "string", "human_frame": "int32",
        "robot_episode_id": "string", "robot_frame": "int32", "cost": "double",
        "features": "string", "run_id": "string"}


def test_paths_are_monotone_and_match_the_ground_truth(aligned):
    truth = {json.loads(l)["pair_id"]: json.loads(l)["human_to_robot"]
             for l in (SIM / "warps.jsonl").read_text().splitlines() if l.strip()}
    rows = aligned["dl"]["rows"]
    by_pair: dict[str, list] = {}
    for r in rows:
        by_pair.setdefault(r["pair_id"], []).append((r["human_frame"], r["robot_frame"]))
    assert set(by_pair) == set(truth)
    for pair, path in by_pair.items():
        path.sort()
        assert path[0] == (0, 0)
        assert path[-1] == (len(truth[pair]) - 1, max(j for _, j in path))
        for (i0, j0), (i1, j1) in zip(path, path[1:]):
            assert 0 <= i1 - i0 <= 1 and 0 <= j1 - j0 <= 1
        # Mean robot frame per human frame of the path (the report's error uses each human
        # frame's posterior median, the last cell of its row except in the last row).
        got = {}
        for i, j in path:
            got.setdefault(i, []).append(j)
        err = sum(abs(round(sum(v) / len(v)) - truth[pair][i]) for i, v in got.items()) / len(got)
        assert err <= 1.0, (pair, err)
    assert all(p["mean_frame_error"] <= 1.0 for p in aligned["rep"]["pairs"]), aligned["rep"]["pairs"]
