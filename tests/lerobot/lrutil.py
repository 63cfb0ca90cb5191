"""Helpers of the LeRobot interop tests (imported by conftest.py and test_lerobot.py)."""

from __future__ import annotations

import io
import itertools
import json
import pickle
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import milvtest  # tests/pyutil (conftest puts it on sys.path)
import write_dataset as wd  # tools/lerobot/write_dataset.py (conftest puts it on sys.path)

HERE = Path(__file__).resolve().parent
TIMEOUT = 300
FPS = 10
SIZE = 64
LENGTHS = (12, 15, 18)  # distinct, so episodes can be matched by length too


# --------------------------------------------------------------------------
# processes


def run(args, ok_codes=(0,), timeout=TIMEOUT) -> subprocess.CompletedProcess:
    return milvtest.run_checked(args, ok_codes, timeout)


def run_json(args, ok_codes=(0,)):
    return milvtest.run_json(args, ok_codes, TIMEOUT)


_counter = itertools.count()


def read_tables(work: Path, *tables: Path) -> list[dict]:
    """deltalake reads of MILV tables, in a subprocess (delta_dump.py)."""
    out = Path(work) / f"delta-{next(_counter)}.pkl"
    p = subprocess.run([sys.executable, str(HERE / "delta_dump.py"), str(out), *map(str, tables)],
                       capture_output=True, text=True, timeout=TIMEOUT)
    if p.returncode != 0 or not out.is_file():
        pytest.fail(f"delta_dump.py exited {p.returncode}\n{p.stdout}\n{p.stderr}")
    with open(out, "rb") as f:
        return pickle.load(f)


# --------------------------------------------------------------------------
# images


def decode_png(data: bytes) -> np.ndarray:
    img = Image.open(io.BytesIO(data))
    assert img.format == "PNG", img.format
    return np.asarray(img.convert("RGB"))


def to_u8(t) -> np.ndarray:
    """LeRobot's float32 [3,H,W] in [0,1] -> uint8 [H,W,3]."""
    a = t.numpy() if hasattr(t, "numpy") else np.asarray(t)
    assert a.dtype == np.float32 and a.ndim == 3 and a.shape[0] == 3, (a.dtype, a.shape)
    assert a.min() >= 0.0 and a.max() <= 1.0
    return np.round(a * 255.0).astype(np.uint8).transpose(1, 2, 0)


def mad(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b.astype(np.float64)).mean())


def neighbour_check(got: np.ndarray, frames: list[np.ndarray], i: int) -> tuple[float, float]:
    """(mad to frames[i], smallest mad to frames[i-1], frames[i+1]): got must be closest to its own."""
    own = mad(got, frames[i])
    others = [mad(got, frames[j]) for j in (i - 1, i + 1) if 0 <= j < len(frames)]
    return own, min(others) if others else float("inf")


def f32_rows(rows) -> np.ndarray:
    return np.asarray(rows, dtype=np.float32)


# --------------------------------------------------------------------------
# LeRobot


def write_lerobot(out: Path, cameras: list[str], images: bool, episodes: int = 3) -> dict:
    """Writes a dataset with LeRobot's own API and returns its ground truth.

    In a subprocess: with several cameras LeRobot encodes them in a fork()ed
    ProcessPoolExecutor, which is better kept out of the (multi-threaded) pytest process.
    """
    args = ["--out", str(out), "--episodes", str(episodes), "--frames", str(LENGTHS[0]),
            "--frame-step", str(LENGTHS[1] - LENGTHS[0]), "--size", f"{SIZE}x{SIZE}", "--fps", str(FPS),
            "--cameras", ",".join(cameras), "--seed", "7"]
    if images:
        args.append("--images")
    run([sys.executable, wd.__file__, *args])
    truth = json.loads(out.with_name(out.name + ".truth.json").read_text())
    truth["path"] = out
    return truth


def load_lerobot(root: Path, **kw):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset("local/x", root=root, video_backend="pyav", **kw)


def lerobot_episodes(ds) -> list[dict]:
    """Per LeRobot episode: task, actions, states, frames per image key (uint8 HWC), indices."""
    out: dict[int, dict] = {}
    keys = list(ds.meta.camera_keys)
    for idx in range(len(ds)):
        it = ds[idx]
        e = int(it["episode_index"])
        ep = out.setdefault(e, {"episode_index": e, "task": it["task"], "actions": [], "states": [],
                                "frames": {k: [] for k in keys}, "frame_index": [], "timestamp": [],
                                "index": []})
        assert it["task"] == ep["task"]
        ep["actions"].append(it["action"].numpy())
        if "observation.state" in it:
            ep["states"].append(it["observation.state"].numpy())
        for k in keys:
            ep["frames"][k].append(to_u8(it[k]))
        ep["frame_index"].append(int(it["frame_index"]))
        ep["timestamp"].append(float(it["timestamp"]))
        ep["index"].append(int(it["index"]))
    eps = [out[e] for e in sorted(out)]
    for ep in eps:
        ep["actions"] = np.stack(ep["actions"])
        ep["states"] = np.stack(ep["states"]) if ep["states"] else None
        ep["length"] = len(ep["actions"])
    return eps


# --------------------------------------------------------------------------
# MILV datasets made without LeRobot


@dataclass
class MilvSource:
    path: Path  # the MILV dataset
    work: Path
    fps: int
    action_names: list
    state_names: list
    # per source folder name: task, actions, states, frames (what was written)
    sources: dict = field(default_factory=dict)
    episodes: list = field(default_factory=list)  # episodes table rows
    frames: dict = field(default_factory=dict)  # episode_id -> frame rows sorted by frame_index
    version: int | None = None


MILV_TASKS = ("pick the cube", "push the cube to the left", "pick the cube")
MILV_ACTION_NAMES = ["dx", "dy", "grip"]
MILV_STATE_NAMES = ["x", "y"]


def make_sources(work: Path) -> dict:
    """Three frame folders of numbered PNGs (12, 15, 18 frames, 64x64) with sidecars."""
    sources = {}
    for e, n in enumerate(LENGTHS):
        name = f"ep{e}"
        folder = work / name
        folder.mkdir(parents=True)
        _, _, frames = wd.episode_arrays(e, n, SIZE, SIZE, 1 + e % 2, seed=21)
        frames = frames[e % 2]  # camera 0 or 1 look: different backgrounds per episode
        for i, img in enumerate(frames):
            Image.fromarray(img).save(folder / f"frame_{i:06d}.png")
        rng = np.random.default_rng([21, e])
        actions = rng.normal(0, 1, (n, len(MILV_ACTION_NAMES))).astype(np.float32)
        actions[:, 2] = (np.arange(n) // 4) % 2
        states = np.cumsum(rng.normal(0, 0.1, (n, len(MILV_STATE_NAMES))), axis=0).astype(np.float32)
        sidecar = {
            "format": "milv-sidecar/1",
            "episode": {"domain": "robot", "task_id": MILV_TASKS[e], "fps": FPS},
            "action_names": MILV_ACTION_NAMES,
            "state_names": MILV_STATE_NAMES,
            "actions": actions.astype(float).tolist(),  # float32 values, exact in JSON
            "states": states.astype(float).tolist(),
        }
        (work / f"{name}.json").write_text(json.dumps(sidecar))
        sources[name] = {"folder": folder, "task": MILV_TASKS[e], "actions": actions, "states": states,
                         "frames": list(frames)}
    return sources


def make_milv_dataset(milv_bin: Path, work: Path) -> MilvSource:
    sources = make_sources(work / "src")
    dataset = work / "ds"
    rep = run_json([milv_bin / "milv-ingest", dataset, *[s["folder"] for s in sources.values()],
                    "--fps", FPS, "--domain", "robot", "--task", "pick the cube", "--json"])
    assert not rep.get("failed"), rep
    assert len(rep["ingested"]) == len(sources), rep
    src = MilvSource(dataset, work, FPS, MILV_ACTION_NAMES, MILV_STATE_NAMES, sources, version=rep.get("version"))
    read_milv(src)
    return src


def read_milv(src) -> None:
    episodes, frames = read_tables(src.work, src.path / "episodes", src.path / "frames")
    src.episodes = episodes["rows"]
    src.frames = {}
    for r in frames["rows"]:
        src.frames.setdefault(r["episode_id"], []).append(r)
    for rows in src.frames.values():
        rows.sort(key=lambda r: r["frame_index"])


def milv_episode_arrays(src, episode_id: str) -> dict:
    rows = src.frames[episode_id]
    return {
        "actions": f32_rows([r["action"] for r in rows]),
        "states": None if rows[0].get("state") is None else f32_rows([r["state"] for r in rows]),
        "frames": [decode_png(r["image"]) for r in rows],
        "frame_index": [r["frame_index"] for r in rows],
        "timestamp_ns": [r["timestamp_ns"] for r in rows],
    }


def source_episode_index(uri: str) -> int:
    m = re.search(r"[#&?]episode=(\d+)", uri)
    assert m, f"source_uri {uri!r} does not name the LeRobot episode (…#episode=N&camera=KEY)"
    return int(m.group(1))


def find_stats(doc: dict) -> dict:
    """`milv-ds stats` JSON: the stats.json shape, possibly wrapped."""
    if "action" in doc:
        return doc
    for k in ("stats", "features"):
        if isinstance(doc.get(k), dict) and "action" in doc[k]:
            return doc[k]
    pytest.fail(f"milv-ds stats: no `action` feature in {list(doc)}")
