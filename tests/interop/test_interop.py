"""Interop: datasets written by the Rust CLIs, read back from Python.

The module fixture builds a dataset from the bundled samples with two
`milv-ingest` runs (first half of the manifest, then the rest), re-runs the full
manifest (everything must be skipped), and builds a second small dataset with
`--frame-encoding raw`.  The Delta tables are then read with `deltalake` +
pyarrow and with polars (in a subprocess, see delta_reader.py) and compared with
the sample clips and their sidecars.
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import av
import milvtest  # tests/pyutil, put on sys.path by conftest.py
import numpy as np
import pytest
from PIL import Image

HERE = Path(__file__).resolve().parent
READER = HERE / "delta_reader.py"
TIMEOUT = 900
MAX_MEAN_ABS_DIFF = 2.0  # video frames: Rust's FFmpeg vs PyAV's FFmpeg, both swscale

EPISODES_SCHEMA = {
    "episode_id": ("string", False),
    "domain": ("string", False),
    "kind": ("string", False),
    "task_id": ("string", True),
    "task_family": ("string", True),
    "pair_id": ("string", True),
    "split": ("string", False),
    "n_frames": ("int64", False),
    "fps": ("double", False),
    "width": ("int32", False),
    "height": ("int32", False),
    "frame_encoding": ("string", False),
    "action_dim": ("int32", True),
    "state_dim": ("int32", True),
    "action_names": ("list<string>", True),
    "state_names": ("list<string>", True),
    "source_uri": ("string", False),
    "source_sha256": ("string", False),
    "sidecar_uri": ("string", True),
    "duration_ns": ("int64", False),
    "ingested_at": ("timestamp[us, tz=UTC]", False),
}
FRAMES_SCHEMA = {
    "episode_id": ("string", False),
    "frame_index": ("int32", False),
    "timestamp_ns": ("int64", False),
    "image": ("binary", False),
    "action": ("list<float>", True),
    "state": ("list<float>", True),
}


# --------------------------------------------------------------------------
# helpers


def run_cli(args: list, ok_codes=(0,)) -> subprocess.CompletedProcess:
    return milvtest.run_checked(args, ok_codes, TIMEOUT)


def run_json(args: list, ok_codes=(0,)):
    return milvtest.run_json(args, ok_codes, TIMEOUT)


_req_counter = itertools.count()


def read_tables(work: Path, reads: list[dict]) -> list[dict]:
    """Run delta_reader.py in a subprocess on a list of reads."""
    req = work / f"read-request-{next(_req_counter)}.json"
    req.write_text(json.dumps({"reads": reads}))
    p = subprocess.run([sys.executable, str(READER), str(req)], capture_output=True, text=True,
                       timeout=TIMEOUT)
    try:
        answer = json.loads(p.stdout)
    except json.JSONDecodeError:
        pytest.fail(f"delta_reader.py exited {p.returncode} without JSON\n--- stdout\n{p.stdout}\n"
                    f"--- stderr\n{p.stderr}")
    if "error" in answer or p.returncode != 0:
        pytest.fail(f"delta_reader.py failed (rc {p.returncode}):\n{answer.get('error')}\n{p.stderr}")
    return answer["results"]


@dataclass
class Sample:
    name: str  # file or folder name, e.g. "human_reach.mp4", "robot_sim_frames"
    path: Path
    sidecar: Path
    meta: dict
    action_names: list | None
    state_names: list | None
    actions: list
    states: list | None
    _frames: list | None = field(default=None, repr=False)

    @property
    def is_folder(self) -> bool:
        return self.path.is_dir()

    @property
    def is_robot(self) -> bool:
        return self.meta.get("domain") == "robot"

    def frames(self) -> list[np.ndarray]:
        """Source frames as HxWx3 uint8 RGB."""
        if self._frames is None:
            if self.is_folder:
                files = sorted(p for p in self.path.iterdir() if p.suffix.lower() == ".png")
                self._frames = [np.asarray(Image.open(p).convert("RGB")) for p in files]
            else:
                with av.open(str(self.path)) as c:
                    self._frames = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
        return self._frames


def parse_sidecar(path: Path):
    if path.suffix == ".json":
        doc = json.loads(path.read_text())
        return (doc.get("episode", {}), doc.get("action_names"), doc.get("state_names"),
                doc.get("actions"), doc.get("states"))
    meta, body = {}, []
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            k, _, v = line[1:].partition(":")
            v = v.strip()
            meta[k.strip()] = float(v) if k.strip() == "fps" else v
        elif line.strip():
            body.append(line)
    rows = list(csv.reader(io.StringIO("\n".join(body))))
    header, data = rows[0], rows[1:]
    a_idx = [i for i, h in enumerate(header) if h.startswith("action.")]
    s_idx = [i for i, h in enumerate(header) if h.startswith("state.")]
    actions = [[float(r[i]) for i in a_idx] for r in data] if a_idx else None
    states = [[float(r[i]) for i in s_idx] for r in data] if s_idx else None
    a_names = [header[i][len("action."):] for i in a_idx] or None
    s_names = [header[i][len("state."):] for i in s_idx] or None
    return meta, a_names, s_names, actions, states


def load_samples(folder: Path, manifest: Path) -> dict[str, Sample]:
    out = {}
    for line in manifest.read_text().splitlines():
        if not line.strip():
            continue
        entry = json.loads(line)
        path = folder / entry["path"]
        sidecar = folder / entry["sidecar"]
        meta, a_names, s_names, actions, states = parse_sidecar(sidecar)
        name = path.name
        out[name] = Sample(name, path, sidecar, meta, a_names, s_names, actions, states)
    return out


def source_name(uri: str) -> str:
    if uri.startswith("file://"):
        uri = uri[len("file://"):]
    return Path(uri.rstrip("/")).name


def f32(rows):
    return None if rows is None else [[float(np.float32(v)) for v in r] for r in rows]


def decode_png(data: bytes) -> np.ndarray:
    img = Image.open(io.BytesIO(data))
    assert img.format == "PNG", img.format
    assert img.mode == "RGB", f"stored PNG should be 8-bit RGB, is {img.mode}"
    return np.asarray(img)


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def log_entries(log) -> list[dict]:
    if isinstance(log, dict):
        for key in ("versions", "log", "entries"):
            if isinstance(log.get(key), list):
                return log[key]
    assert isinstance(log, list), f"milv-ds log --json should print a list, got {type(log).__name__}"
    return log


def group_rows(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for r in rows:
        out.setdefault(r["episode_id"], []).append(r)
    return out


# --------------------------------------------------------------------------
# the datasets


@pytest.fixture(scope="module")
def ds(milv_bin: Path, samples_dir: Path, tmp_path_factory) -> SimpleNamespace:
    import shutil

    work = tmp_path_factory.mktemp("interop")
    src = work / "samples"
    shutil.copytree(samples_dir, src, symlinks=True)
    lines = [ln for ln in (src / "manifest.jsonl").read_text().splitlines() if ln.strip()]
    assert len(lines) >= 4, "samples manifest is too small for this test"
    half = len(lines) // 2
    part1, part2 = src / "part1.jsonl", src / "part2.jsonl"
    part1.write_text("\n".join(lines[:half]) + "\n")
    part2.write_text("\n".join(lines[half:]) + "\n")
    samples = load_samples(src, src / "manifest.jsonl")
    names1 = [Path(json.loads(ln)["path"]).name for ln in lines[:half]]
    names2 = [Path(json.loads(ln)["path"]).name for ln in lines[half:]]

    ingest, dsbin = milv_bin / "milv-ingest", milv_bin / "milv-ds"
    dataset = work / "dataset"
    r1 = run_json([ingest, dataset, "--manifest", part1, "--json"])
    r2 = run_json([ingest, dataset, "--manifest", part2, "--json"])
    r3 = run_json([ingest, dataset, "--manifest", src / "manifest.jsonl", "--json"])
    log = log_entries(run_json([dsbin, "log", dataset, "--json"]))

    by_version = {e["version"]: e for e in log}
    assert r1["version"] in by_version, f"version {r1['version']} missing from log {log}"
    assert r2["version"] in by_version, f"version {r2['version']} missing from log {log}"
    pins1, pins2 = by_version[r1["version"]]["tables"], by_version[r2["version"]]["tables"]

    ep_tab, fr_tab = str(dataset / "episodes"), str(dataset / "frames")
    dump1, dump2 = work / "dump-frames", work / "dump-raw"

    def rd(path, version, reader, dump=False, dump_dir=None):
        return {"path": path, "version": version, "reader": reader, "dump": dump,
                "dump_dir": None if dump_dir is None else str(dump_dir)}

    reads = read_tables(work, [
        rd(ep_tab, pins1["episodes"], "deltalake"),
        rd(fr_tab, pins1["frames"], "deltalake"),
        rd(ep_tab, pins2["episodes"], "deltalake", dump=True),
        rd(fr_tab, pins2["frames"], "deltalake", dump=True, dump_dir=dump1),
        rd(ep_tab, None, "deltalake"),
        rd(fr_tab, None, "deltalake"),
        rd(ep_tab, pins1["episodes"], "polars"),
        rd(fr_tab, pins1["frames"], "polars"),
        rd(ep_tab, pins2["episodes"], "polars", dump=True),
        rd(fr_tab, pins2["frames"], "polars"),
    ])
    keys = ["ep1", "fr1", "ep2", "fr2", "ep_latest", "fr_latest", "pl_ep1", "pl_fr1", "pl_ep2", "pl_fr2"]
    tables = dict(zip(keys, reads))

    # A second dataset, given inputs on the command line, with raw RGB24 frames.
    raw_inputs = [s for s in samples.values() if s.is_folder][:1] + \
                 [s for s in samples.values() if not s.is_folder][:1]
    raw_dataset = work / "dataset_raw"
    r_raw = run_json([ingest, raw_dataset, *[s.path for s in raw_inputs], "--frame-encoding", "raw",
                      "--json"])
    raw_reads = read_tables(work, [
        rd(str(raw_dataset / "episodes"), None, "deltalake", dump=True),
        rd(str(raw_dataset / "frames"), None, "deltalake", dump=True, dump_dir=dump2),
    ])

    return SimpleNamespace(
        work=work, src=src, dataset=dataset, raw_dataset=raw_dataset, dsbin=dsbin,
        samples=samples, names1=names1, names2=names2,
        r1=r1, r2=r2, r3=r3, r_raw=r_raw, log=log, pins1=pins1, pins2=pins2,
        raw_inputs=raw_inputs, raw_ep=raw_reads[0], raw_fr=raw_reads[1], **tables,
    )


def sample_of(ds, ep: dict) -> Sample:
    name = source_name(ep["source_uri"])
    assert name in ds.samples, f"episode {ep['episode_id']} has source_uri {ep['source_uri']!r}, not a sample"
    return ds.samples[name]


# --------------------------------------------------------------------------
# CLI reports and versions


def test_ingest_reports(ds):
    for report, names in ((ds.r1, ds.names1), (ds.r2, ds.names2)):
        assert report["failed"] == [], report["failed"]
        got = sorted(source_name(e["source"]) for e in report["ingested"])
        assert got == sorted(names)
        for e in report["ingested"]:
            s = ds.samples[source_name(e["source"])]
            assert e["n_frames"] == len(s.actions), (s.name, e)
            assert e["episode_id"]
        assert report["frames"] == sum(e["n_frames"] for e in report["ingested"])
    assert ds.r2["version"] > ds.r1["version"]


def test_reingest_skips_everything(ds):
    assert ds.r3["ingested"] == []
    assert ds.r3["failed"] == []
    assert len(ds.r3["skipped"]) == len(ds.samples)
    assert ds.r3["version"] == ds.r2["version"], "a no-op ingest must not make a new dataset version"
    assert max(e["version"] for e in ds.log) == ds.r2["version"]


def test_log_pins_table_versions(ds):
    for v in (ds.r1["version"], ds.r2["version"]):
        entry = next(e for e in ds.log if e["version"] == v)
        assert set(entry["tables"]) >= {"episodes", "frames"}, entry
        assert entry.get("tool_version"), entry
        assert "ingest" in entry.get("command", ""), entry
    assert ds.pins2["episodes"] > ds.pins1["episodes"]
    assert ds.pins2["frames"] > ds.pins1["frames"]
    assert ds.ep1["loaded_version"] == ds.pins1["episodes"]
    assert ds.fr2["loaded_version"] == ds.pins2["frames"]


def test_time_travel_counts(ds):
    n1, n_all = len(ds.names1), len(ds.samples)
    f1 = sum(len(ds.samples[n].actions) for n in ds.names1)
    f_all = sum(len(s.actions) for s in ds.samples.values())
    assert ds.ep1["num_rows"] == n1
    assert ds.ep2["num_rows"] == n_all
    assert ds.fr1["num_rows"] == f1
    assert ds.fr2["num_rows"] == f_all
    assert ds.ep1["num_rows"] < ds.ep2["num_rows"]
    assert ds.fr1["num_rows"] < ds.fr2["num_rows"]
    # The no-op re-ingest left the tables where version 2 pinned them.
    assert ds.ep_latest["num_rows"] == n_all
    assert ds.fr_latest["num_rows"] == f_all


def test_milv_ds_info_and_verify_at_versions(ds):
    n1, n_all = len(ds.names1), len(ds.samples)
    f1 = sum(len(ds.samples[n].actions) for n in ds.names1)
    f_all = sum(len(s.actions) for s in ds.samples.values())
    for v, n, f, pins in ((ds.r1["version"], n1, f1, ds.pins1), (ds.r2["version"], n_all, f_all, ds.pins2)):
        info = run_json([ds.dsbin, "info", f"{ds.dataset}@{v}", "--json"])
        assert info, f"milv-ds info {ds.dataset}@{v} --json printed an empty document"
        # The info document's shape is not part of the interop contract; check what it has.
        if isinstance(info, dict):
            if "episodes" in info:
                assert info["episodes"] == n, info
            if "frames" in info:
                assert info["frames"] == f, info
            if "version" in info:
                assert info["version"] == v, info
            for t in ("episodes", "frames"):
                dv = info.get("tables", {}).get(t, {})
                if isinstance(dv, dict) and "delta_version" in dv:
                    assert dv["delta_version"] == pins[t], info
        run_cli([ds.dsbin, "verify", f"{ds.dataset}@{v}"])
    run_cli([ds.dsbin, "verify", ds.dataset])


# --------------------------------------------------------------------------
# schemas


@pytest.mark.parametrize("which", ["ep1", "ep2", "fr1", "fr2"])
def test_arrow_schema(ds, which):
    expected = EPISODES_SCHEMA if which.startswith("ep") else FRAMES_SCHEMA
    cols = getattr(ds, which)["columns"]
    for name, (typ, nullable) in expected.items():
        assert name in cols, f"{which}: column {name} missing; have {sorted(cols)}"
        assert cols[name]["type"] == typ, f"{which}.{name}: {cols[name]['raw_type']}, want {typ}"
        if nullable:
            assert cols[name]["nullable"], f"{which}.{name} must be nullable in the Delta schema"


@pytest.mark.parametrize("which", ["pl_ep1", "pl_ep2", "pl_fr1", "pl_fr2"])
def test_polars_reads(ds, which):
    expected = EPISODES_SCHEMA if "_ep" in which else FRAMES_SCHEMA
    res = getattr(ds, which)
    cols = res["columns"]
    for name, (typ, _) in expected.items():
        assert name in cols, f"{which}: column {name} missing"
        assert cols[name]["type"] == typ, f"{which}.{name}: polars {cols[name]['raw_type']}, want {typ}"
    same = getattr(ds, which[3:])
    assert res["num_rows"] == same["num_rows"], "polars and deltalake disagree on the row count"


def test_polars_and_deltalake_agree_on_episodes(ds):
    def key(rows):
        return sorted((r["episode_id"], r["n_frames"], r["width"], r["height"], r["source_sha256"])
                      for r in rows)
    assert key(ds.pl_ep2["rows"]) == key(ds.ep2["rows"])


# --------------------------------------------------------------------------
# contents


def test_no_nulls_in_required_columns(ds):
    for rows, schema in ((ds.ep2["rows"], EPISODES_SCHEMA), (ds.fr2["rows"], FRAMES_SCHEMA)):
        for r in rows:
            for name, (_, nullable) in schema.items():
                if not nullable and name != "image":
                    assert r[name] is not None, f"{name} is null in {r.get('episode_id')}"
    assert all(r["image_file"] is not None for r in ds.fr2["rows"])


def test_episode_metadata(ds):
    ids = [ep["episode_id"] for ep in ds.ep2["rows"]]
    assert len(ids) == len(set(ids)), "episode_id must be unique"
    seen = set()
    for ep in ds.ep2["rows"]:
        s = sample_of(ds, ep)
        seen.add(s.name)
        for key in ("domain", "kind", "task_id", "task_family", "pair_id", "split"):
            assert ep[key] == s.meta.get(key), (s.name, key, ep[key], s.meta.get(key))
        assert ep["fps"] == pytest.approx(float(s.meta["fps"]))
        h, w = s.frames()[0].shape[:2]
        assert (ep["width"], ep["height"]) == (w, h), s.name
        assert ep["frame_encoding"] == "png"
        assert ep["n_frames"] == len(s.actions) == len(s.frames()), s.name
        assert ep["action_dim"] == len(s.actions[0])
        assert ep["action_names"] == s.action_names
        if s.states is None:
            assert ep["state_dim"] is None
            assert not ep["state_names"]
        else:
            assert ep["state_dim"] == len(s.states[0])
            assert ep["state_names"] == s.state_names
        assert ep["sidecar_uri"] and source_name(ep["sidecar_uri"]) == s.sidecar.name
        assert len(ep["source_sha256"]) == 64 and int(ep["source_sha256"], 16) >= 0
        if not s.is_folder:
            assert ep["source_sha256"] == sha256_file(s.path), s.name
        period = 1e9 / float(s.meta["fps"])
        n = ep["n_frames"]
        assert (n - 1) * period - 1e6 <= ep["duration_ns"] <= (n + 1) * period + 1e6, (s.name, ep["duration_ns"])
        assert ep["ingested_at"]
    assert seen == set(ds.samples)


def test_frames_match_episodes_and_sidecars(ds):
    frames = group_rows(ds.fr2["rows"])
    for ep in ds.ep2["rows"]:
        s = sample_of(ds, ep)
        rows = frames.get(ep["episode_id"], [])
        assert len(rows) == ep["n_frames"], f"{s.name}: {len(rows)} frame rows, n_frames {ep['n_frames']}"
        assert [r["frame_index"] for r in rows] == list(range(len(rows)))
        ts = [r["timestamp_ns"] for r in rows]
        assert all(b > a for a, b in zip(ts, ts[1:])), f"{s.name}: timestamps not increasing"
        period = 1e9 / float(s.meta["fps"])
        for i, t in enumerate(ts):
            assert abs((t - ts[0]) - i * period) <= 1e6, f"{s.name} frame {i}: timestamp {t}"
        assert [r["action"] for r in rows] == f32(s.actions), s.name
        if s.states is None:
            assert all(r["state"] is None for r in rows), s.name
        else:
            assert [r["state"] for r in rows] == f32(s.states), s.name


def test_png_folder_frames_are_exact(ds):
    frames = group_rows(ds.fr2["rows"])
    checked = 0
    for ep in ds.ep2["rows"]:
        s = sample_of(ds, ep)
        if not s.is_folder:
            continue
        for r, src in zip(frames[ep["episode_id"]], s.frames()):
            got = decode_png(Path(r["image_file"]).read_bytes())
            assert got.shape == src.shape
            assert np.array_equal(got, src), f"{s.name} frame {r['frame_index']} differs from its PNG"
            checked += 1
    assert checked > 0, "the samples have no frame-folder episode"


def test_video_frames_match_pyav_decode(ds):
    frames = group_rows(ds.fr2["rows"])
    checked = 0
    for ep in ds.ep2["rows"]:
        s = sample_of(ds, ep)
        if s.is_folder:
            continue
        src = s.frames()
        rows = frames[ep["episode_id"]]
        assert len(rows) == len(src), f"{s.name}: {len(rows)} stored frames, PyAV decodes {len(src)}"
        for r, ref in zip(rows, src):
            got = decode_png(Path(r["image_file"]).read_bytes())
            assert got.shape == ref.shape, s.name
            mad = float(np.abs(got.astype(np.int16) - ref.astype(np.int16)).mean())
            assert mad <= MAX_MEAN_ABS_DIFF, f"{s.name} frame {r['frame_index']}: mean abs diff {mad:.2f}"
            checked += 1
    assert checked > 0


def test_raw_frame_encoding(ds):
    assert ds.r_raw["failed"] == []
    assert len(ds.r_raw["ingested"]) == len(ds.raw_inputs)
    png_frames = group_rows(ds.fr2["rows"])
    png_ids = {sample_of(ds, ep).name: ep["episode_id"] for ep in ds.ep2["rows"]}
    raw_frames = group_rows(ds.raw_fr["rows"])
    for ep in ds.raw_ep["rows"]:
        s = sample_of(ds, ep)
        assert ep["frame_encoding"] == "raw"
        w, h = ep["width"], ep["height"]
        rows = raw_frames[ep["episode_id"]]
        assert len(rows) == ep["n_frames"] == len(s.actions)
        for r, png_row in zip(rows, png_frames[png_ids[s.name]]):
            data = Path(r["image_file"]).read_bytes()
            assert len(data) == w * h * 3, f"{s.name}: raw frame of {len(data)} bytes for {w}x{h}"
            got = np.frombuffer(data, np.uint8).reshape(h, w, 3)
            want = decode_png(Path(png_row["image_file"]).read_bytes())
            assert np.array_equal(got, want), f"{s.name} frame {r['frame_index']}: raw != png-decoded"
            if s.is_folder:
                assert np.array_equal(got, s.frames()[r["frame_index"]])
