"""MILV <-> LeRobot v3.0, checked with LeRobot 0.6.1 itself (offline, `video_backend="pyav"`).

Export: a MILV dataset made from frame folders + sidecars goes through
`milv-export lerobot` (--images and --video) and is read back with `LeRobotDataset`.
Import: datasets written by LeRobot's own writer (tools/lerobot/write_dataset.py; two
cameras; AV1 video and inline images) go through `milv-ingest --from-lerobot` and the
MILV tables (read with deltalake) are compared with what `LeRobotDataset` returns.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import lrutil as U
from conftest import CAMERAS

# A video frame may differ from its source by coding noise; this bounds it loosely (the real
# check is that it is closer to its own source than to the neighbouring frames).
VIDEO_MAD_LIMIT = 16.0  # of 255
# MILV's and LeRobot's decodes of the same AV1 stream (both FFmpeg + libdav1d, RGB conversion).
DECODE_MAD_LIMIT = 3.0  # of 255


# ==========================================================================
# LeRobot's writer itself (no MILV needed): the ground truth the import tests rely on


@pytest.mark.parametrize("kind", ["video", "images"])
def test_lerobot_writer_round_trip(kind, lerobot_video, lerobot_images):
    truth = lerobot_video if kind == "video" else lerobot_images
    ds = U.load_lerobot(truth["path"])
    assert ds.num_episodes == len(truth["episodes"]) == 3
    assert len(ds) == sum(U.LENGTHS)
    eps = U.lerobot_episodes(ds)
    for e, (ep, t) in enumerate(zip(eps, truth["episodes"])):
        assert ep["task"] == t["task"]
        assert ep["length"] == t["length"] == U.LENGTHS[e]
        assert np.array_equal(ep["actions"], U.f32_rows(t["actions"]))
        assert np.array_equal(ep["states"], U.f32_rows(t["states"]))
        _, _, src = U.wd.episode_arrays(e, t["length"], U.SIZE, U.SIZE, len(CAMERAS), truth["seed"])
        for c, key in enumerate(CAMERAS):
            for i, got in enumerate(ep["frames"][key]):
                if kind == "images":
                    assert np.array_equal(got, src[c][i]), (key, e, i)
                else:
                    own, other = U.neighbour_check(got, src[c], i)
                    assert own < other and own < VIDEO_MAD_LIMIT, (key, e, i, own, other)
    if kind == "video":
        for key in CAMERAS:
            assert ds.meta.features[key]["info"]["video.codec"] == "av1"


# ==========================================================================
# export: MILV -> LeRobot


@pytest.fixture(scope="module", params=["images", "video"])
def exported(request, milv_bin, milv_source, tmp_path_factory):
    kind = request.param
    out = tmp_path_factory.mktemp(f"export-{kind}") / "lerobot"
    rep = U.run_json([milv_bin / "milv-export", "lerobot", milv_source.path, "-o", out, f"--{kind}", "--json"])
    ds = U.load_lerobot(out)
    eps = U.lerobot_episodes(ds)
    # Map every LeRobot episode to its MILV episode by content (actions), not by order.
    milv = {r["episode_id"]: U.milv_episode_arrays(milv_source, r["episode_id"]) for r in milv_source.episodes}
    by_ep = {r["episode_id"]: r for r in milv_source.episodes}
    pairs = []
    for ep in eps:
        hits = [eid for eid, m in milv.items()
                if len(m["actions"]) == ep["length"] and np.array_equal(m["actions"], ep["actions"])]
        assert len(hits) == 1, f"LeRobot episode {ep['episode_index']} matches MILV episodes {hits}"
        pairs.append((ep, by_ep[hits[0]], milv[hits[0]]))
    return {"kind": kind, "out": out, "report": rep, "ds": ds, "pairs": pairs, "src": milv_source}


def test_export_loads_offline(exported):
    ds, src = exported["ds"], exported["src"]
    total = sum(len(v) for v in src.frames.values())
    assert ds.num_episodes == len(src.episodes) == 3
    assert len(ds) == ds.meta.total_frames == total
    assert ds.fps == U.FPS
    info = json.loads((exported["out"] / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0"
    feats = ds.meta.features
    img = feats["observation.image"]
    assert img["dtype"] == ("video" if exported["kind"] == "video" else "image")
    assert list(img["shape"]) == [U.SIZE, U.SIZE, 3]
    assert feats["action"]["dtype"] == "float32"
    assert list(feats["action"]["shape"]) == [len(U.MILV_ACTION_NAMES)]
    assert list(feats["action"]["names"]) == U.MILV_ACTION_NAMES
    assert feats["observation.state"]["dtype"] == "float32"
    assert list(feats["observation.state"]["names"]) == U.MILV_STATE_NAMES
    for k in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert k in feats, k
    if exported["kind"] == "video":
        # LeRobot's own AV1 encoder and settings (SVT-AV1 takes frames of 64x64 and up).
        assert exported["report"]["video_encoder"] == "libsvtav1", exported["report"]
        assert ds.meta.video_keys == ["observation.image"]
        if "info" in img:  # optional for RGB video (LeRobot only parses it for depth)
            assert img["info"]["video.codec"] == "av1"
        mp4s = sorted((exported["out"] / "videos" / "observation.image").glob("chunk-*/file-*.mp4"))
        assert mp4s, "no videos/observation.image/chunk-XXX/file-YYY.mp4"
        import av

        n = 0
        for path in mp4s:
            with av.open(str(path)) as c:
                s = c.streams.video[0]
                assert s.codec_context.codec.name in ("libdav1d", "av1", "libaom-av1"), s.codec_context.codec.name
                assert (s.codec_context.width, s.codec_context.height) == (U.SIZE, U.SIZE)
                n += sum(1 for _ in c.decode(s))
        assert n == total
    else:
        assert ds.meta.video_keys == [] and not list(exported["out"].rglob("*.mp4"))


def test_export_rows_equal_milv(exported):
    index = 0
    lengths = []
    for e, (ep, row, m) in enumerate(exported["pairs"]):
        assert ep["episode_index"] == e
        n = len(m["actions"])
        assert ep["length"] == n == row["n_frames"]
        lengths.append(n)
        assert ep["actions"].dtype == np.float32
        assert np.array_equal(ep["actions"].view(np.uint32), m["actions"].view(np.uint32))
        assert np.array_equal(ep["states"].view(np.uint32), m["states"].view(np.uint32))
        assert isinstance(ep["task"], str) and ep["task"] == row["task_id"]
        assert ep["frame_index"] == list(range(n))
        assert ep["index"] == list(range(index, index + n))
        index += n
        want_ts = [float(np.float32(i / U.FPS)) for i in range(n)]
        assert ep["timestamp"] == want_ts
    assert sorted(lengths) == sorted(U.LENGTHS)
    tasks = {ep["task"] for ep, _, _ in exported["pairs"]}
    assert tasks == set(U.MILV_TASKS)


def test_export_images(exported):
    for ep, _, m in exported["pairs"]:
        got = ep["frames"]["observation.image"]
        assert len(got) == len(m["frames"])
        for i, g in enumerate(got):
            assert g.shape == (U.SIZE, U.SIZE, 3)
            if exported["kind"] == "images":
                assert np.array_equal(g, m["frames"][i]), f"episode {ep['episode_index']} frame {i}"
            else:
                own, other = U.neighbour_check(g, m["frames"], i)
                assert own < other, f"episode {ep['episode_index']} frame {i}: {own:.2f} vs neighbour {other:.2f}"
                assert own < VIDEO_MAD_LIMIT, f"episode {ep['episode_index']} frame {i}: mad {own:.2f}"


def test_export_delta_timestamps(exported):
    fps = U.FPS
    dts = {"action": [-1 / fps, 0, 1 / fps], "observation.image": [-1 / fps, 0]}
    dd = U.load_lerobot(exported["out"], delta_timestamps=dts)
    assert len(dd) == len(exported["ds"])
    pairs = exported["pairs"]
    for idx in range(len(dd)):
        it = dd[idx]
        ep, _, m = pairs[int(it["episode_index"])]
        i, n = int(it["frame_index"]), ep["length"]
        assert it["action"].shape == (3, len(U.MILV_ACTION_NAMES))
        assert it["action_is_pad"].tolist() == [i == 0, False, i == n - 1], (idx, i, n)
        for k, off in enumerate((-1, 0, 1)):
            j = min(max(i + off, 0), n - 1)  # LeRobot repeats the edge frame under a pad
            assert np.array_equal(it["action"][k].numpy(), m["actions"][j]), (idx, k)
        assert it["observation.image"].shape == (2, 3, U.SIZE, U.SIZE)
        assert it["observation.image_is_pad"].tolist() == [i == 0, False]
        prev = U.to_u8(it["observation.image"][0])
        cur = U.to_u8(it["observation.image"][1])
        j = max(i - 1, 0)
        if exported["kind"] == "images":
            assert np.array_equal(prev, m["frames"][j]) and np.array_equal(cur, m["frames"][i])
        else:
            assert U.neighbour_check(cur, m["frames"], i)[0] < U.neighbour_check(cur, m["frames"], i)[1]
            own, other = U.neighbour_check(prev, m["frames"], j)
            assert own < other, (idx, "previous frame", own, other)


def test_export_dataloader(exported):
    import torch

    dl = torch.utils.data.DataLoader(exported["ds"], batch_size=4, shuffle=False, num_workers=0)
    batch = next(iter(dl))
    assert batch["observation.image"].shape == (4, 3, U.SIZE, U.SIZE)
    assert batch["observation.image"].dtype == torch.float32
    assert batch["action"].shape == (4, len(U.MILV_ACTION_NAMES))
    assert batch["observation.state"].shape == (4, len(U.MILV_STATE_NAMES))
    assert batch["index"].tolist() == [0, 1, 2, 3]
    assert len(batch["task"]) == 4 and all(isinstance(t, str) for t in batch["task"])
    ep0, _, m0 = exported["pairs"][0]
    assert np.array_equal(batch["action"].numpy(), m0["actions"][:4])
    assert batch["task"] == [ep0["task"]] * 4


STAT_KEYS = {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}


def test_export_stats_json(exported):
    stats = json.loads((exported["out"] / "meta" / "stats.json").read_text())
    acts = np.concatenate([m["actions"] for _, _, m in exported["pairs"]]).astype(np.float64)
    total = len(acts)
    a = stats["action"]
    assert set(a) >= STAT_KEYS, sorted(a)
    for k in STAT_KEYS - {"count"}:
        assert np.asarray(a[k]).shape == (len(U.MILV_ACTION_NAMES),), k
    assert list(np.asarray(a["count"]).reshape(-1)) == [total]
    np.testing.assert_allclose(a["min"], acts.min(0), rtol=1e-6)
    np.testing.assert_allclose(a["max"], acts.max(0), rtol=1e-6)
    np.testing.assert_allclose(a["mean"], acts.mean(0), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(a["std"], acts.std(0), rtol=1e-5, atol=1e-7)
    for lo, hi in (("min", "q01"), ("q01", "q10"), ("q10", "q50"), ("q50", "q90"), ("q90", "q99"), ("q99", "max")):
        assert np.all(np.asarray(a[lo]) <= np.asarray(a[hi]) + 1e-6), (lo, hi)
    im = stats["observation.image"]
    assert set(im) >= STAT_KEYS, sorted(im)
    for k in STAT_KEYS - {"count"}:
        v = np.asarray(im[k])
        assert v.shape == (3, 1, 1), (k, v.shape)
        assert np.all((v >= 0) & (v <= 1)), (k, v)  # images are /255
    frames = np.stack([f for _, _, m in exported["pairs"] for f in m["frames"]]).astype(np.float64) / 255
    np.testing.assert_allclose(np.asarray(im["mean"]).reshape(3), frames.mean((0, 1, 2)), atol=2e-3)
    for key in ("observation.state", "timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert key in stats, key
    # LeRobot's own loader reads them (policies normalise with them).
    assert set(exported["ds"].meta.stats["action"]) >= STAT_KEYS


def test_milv_ds_stats_agree_with_stats_json(exported, milv_bin):
    ours = U.find_stats(U.run_json([milv_bin / "milv-ds", "stats", exported["src"].path]))
    theirs = json.loads((exported["out"] / "meta" / "stats.json").read_text())
    for k in ("mean", "std", "min", "max"):
        np.testing.assert_allclose(ours["action"][k], theirs["action"][k], rtol=1e-5, atol=1e-7, err_msg=k)
    assert set(ours["action"]) >= STAT_KEYS


# ==========================================================================
# import: LeRobot -> MILV


@pytest.fixture(scope="module", params=["video", "images"])
def imported(request, milv_bin, lerobot_video, lerobot_images, tmp_path_factory):
    truth = lerobot_video if request.param == "video" else lerobot_images
    work = tmp_path_factory.mktemp(f"import-{request.param}")
    dataset = work / "ds"
    cmd = [milv_bin / "milv-ingest", dataset, "--from-lerobot", truth["path"], "--camera", CAMERAS[0], "--json"]
    rep = U.run_json(cmd)
    src = U.MilvSource(dataset, work, U.FPS, truth["action_names"], truth["state_names"], version=rep.get("version"))
    U.read_milv(src)
    ref = U.lerobot_episodes(U.load_lerobot(truth["path"]))
    by_index = {}
    for row in src.episodes:
        e = U.source_episode_index(row["source_uri"])
        assert e not in by_index, f"two MILV episodes from LeRobot episode {e}"
        by_index[e] = row
    return {"kind": request.param, "truth": truth, "report": rep, "cmd": cmd, "src": src, "ref": ref,
            "by_index": by_index}


def test_import_report(imported):
    rep = imported["report"]
    assert not rep.get("failed"), rep
    assert len(rep["ingested"]) == 3, rep
    assert sorted(r["n_frames"] for r in rep["ingested"]) == sorted(U.LENGTHS)
    assert {r["episode_id"] for r in rep["ingested"]} == {r["episode_id"] for r in imported["src"].episodes}
    assert isinstance(rep["version"], int)


def test_import_episode_metadata(imported):
    truth, by_index = imported["truth"], imported["by_index"]
    assert sorted(by_index) == [0, 1, 2]
    for e, t in enumerate(truth["episodes"]):
        row = by_index[e]
        # The camera taken, and the other cameras kept in the episode's metadata.
        assert f"#episode={e}&camera={CAMERAS[0]}&other_cameras={CAMERAS[1]}" in row["source_uri"], row["source_uri"]
        assert row["n_frames"] == t["length"]
        assert row["task_id"] == t["task"]
        assert row["task_family"] == truth["path"].name
        assert row["domain"] == "robot"
        assert math.isclose(float(row["fps"]), truth["fps"])
        assert (row["width"], row["height"]) == (truth["width"], truth["height"])
        assert list(row["action_names"]) == truth["action_names"]
        assert list(row["state_names"]) == truth["state_names"]


def test_import_rows_equal_lerobot(imported):
    src, ref, by_index, truth = imported["src"], imported["ref"], imported["by_index"], imported["truth"]
    for e, ep in enumerate(ref):
        m = U.milv_episode_arrays(src, by_index[e]["episode_id"])
        n = ep["length"]
        assert len(m["actions"]) == n == truth["episodes"][e]["length"]
        assert m["frame_index"] == list(range(n))
        assert all(b > a for a, b in zip(m["timestamp_ns"], m["timestamp_ns"][1:]))
        assert np.array_equal(m["actions"].view(np.uint32), ep["actions"].view(np.uint32)), e
        assert np.array_equal(m["states"].view(np.uint32), ep["states"].view(np.uint32)), e
        assert np.array_equal(m["actions"], U.f32_rows(truth["episodes"][e]["actions"]))


def test_import_images_match_lerobot(imported):
    src, ref, by_index = imported["src"], imported["ref"], imported["by_index"]
    for e, ep in enumerate(ref):
        m = U.milv_episode_arrays(src, by_index[e]["episode_id"])
        theirs = ep["frames"][CAMERAS[0]]
        assert len(m["frames"]) == len(theirs)
        for i, ours in enumerate(m["frames"]):
            assert ours.shape == (U.SIZE, U.SIZE, 3)
            if imported["kind"] == "images":
                assert np.array_equal(ours, theirs[i]), f"episode {e} frame {i}"
            else:
                own, other = U.neighbour_check(ours, theirs, i)
                assert own < other, f"episode {e} frame {i}: {own:.2f} vs neighbour {other:.2f}"
                assert own < DECODE_MAD_LIMIT, f"episode {e} frame {i}: mad {own:.2f} vs LeRobot's decode"


def test_reimport_is_a_no_op(imported):
    rep = U.run_json(imported["cmd"])
    assert rep["ingested"] == [], rep
    assert not rep.get("failed"), rep
    assert rep["version"] == imported["report"]["version"]
    skipped = rep.get("skipped")
    assert (len(skipped) if isinstance(skipped, list) else skipped) == 3, rep
    before = imported["src"]
    after = U.MilvSource(before.path, before.work, before.fps, [], [])
    U.read_milv(after)
    assert len(after.episodes) == 3
    assert sum(map(len, after.frames.values())) == sum(U.LENGTHS)


def test_import_needs_camera_when_several(milv_bin, lerobot_video, tmp_path):
    # A fatal error (exit 1): nothing was ingested, and the message lists the cameras.
    p = U.run([milv_bin / "milv-ingest", tmp_path / "ds", "--from-lerobot", lerobot_video["path"], "--json"],
              ok_codes=(1,))
    assert "pick one with --camera" in p.stderr, p.stderr
    for key in CAMERAS:
        assert key in p.stderr, p.stderr
