"""`milv-export` output read with the ecosystem's own readers: the MCAP file with the `mcap`
Python reader (CRCs validated, protobuf messages decoded from the schemas embedded in the
file), compared bit for bit with the imagined table read by deltalake; the .rrd with
rerun-sdk (`rerun rrd verify`, entity paths and row counts, the blueprint store)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

READ_MCAP = textwrap.dedent(
    """
    import io, json, os, sys
    import numpy as np
    from deltalake import DeltaTable
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    from mcap.reader import make_reader, NonSeekingReader

    path, table = sys.argv[1], sys.argv[2]
    classes = {}
    def decode(schema, data):
        if schema.id not in classes:
            fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
            pool = descriptor_pool.DescriptorPool()
            for fd in fds.file:
                pool.Add(fd)
            classes[schema.id] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
        return classes[schema.id].FromString(data)

    out = {"topics": {}, "schemas": {}, "encodings": {}, "latent_mismatch": 0, "action_mismatch": 0,
           "image_mismatch": 0, "latents": 0, "actions": 0, "log_times_sorted": True}
    rows = {(r["episode_id"], r["frame_index"]): r for r in DeltaTable(table).to_pyarrow_table().to_pylist()}
    with open(path, "rb") as f:
        r = make_reader(f, validate_crcs=True)
        summary = r.get_summary()
        out["stats"] = {c.topic: summary.statistics.channel_message_counts.get(i, 0)
                        for i, c in summary.channels.items()}
        out["chunks"] = len(summary.chunk_indexes)
        out["compression"] = sorted({c.compression for c in summary.chunk_indexes})
        # Every chunk with messages is indexed (the first holds only schema and channel records).
        out["unindexed_chunks"] = sum(not c.message_index_offsets for c in summary.chunk_indexes)
        last = -1
        for schema, channel, message in r.iter_messages(log_time_order=True):
            t = channel.topic
            out["topics"][t] = out["topics"].get(t, 0) + 1
            out["schemas"][t] = schema.name
            out["encodings"][t] = [schema.encoding, channel.message_encoding]
            last = message.log_time
            if schema.encoding == "protobuf":
                m = decode(schema, message.data)
            else:
                m = json.loads(message.data)
            if t == "/imagined/latent":
                row = rows[(m.episode_id, m.frame_index)]
                out["latents"] += 1
                same = (m.data == row["latent"] and m.dtype == row["latent_dtype"]
                        and list(m.shape) == list(row["latent_shape"]))
                out["latent_mismatch"] += not same
                out["latent_decoded_shape"] = list(np.frombuffer(m.data, dtype=np.float16).reshape(list(m.shape)).shape)
            elif t == "/imagined/action":
                row = rows[(m["episode_id"], m["frame_index"])]
                out["actions"] += 1
                got = np.array([m["dx"], m["dy"]], dtype=np.float32)
                want = np.array(row["action"], dtype=np.float32)
                out["action_mismatch"] += not np.array_equal(got.view(np.uint32), want.view(np.uint32))
            elif t == "/imagined/image":
                out["image_mismatch"] += m.format != "png" or bytes(m.data[:8]) != b"\\x89PNG\\r\\n\\x1a\\n"
        out["metadata"] = {m.name: dict(m.metadata) for m in r.iter_metadata() if m.name == "milv"}
        out["episode_records"] = sum(1 for m in r.iter_metadata() if m.name == "episode")
        out["attachments"] = [[a.name, a.media_type, json.loads(a.data)] for a in r.iter_attachments()]
    # A streaming pass over the whole file also checks the data section's CRC.
    with open(path, "rb") as f:
        n = sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages())
    out["streamed"] = n
    print(json.dumps(out)); sys.stdout.flush(); os._exit(0)
    """
)

READ_RRD = textwrap.dedent(
    """
    import collections, json, os, sys
    from rerun.experimental import RrdReader
    r = RrdReader(sys.argv[1])
    rows = collections.Counter()
    timelines = set()
    for ch in r.stream().to_chunks():
        if not ch.is_static:
            rows[ch.entity_path] += ch.num_rows
            timelines.update(ch.timeline_names)
    kinds = collections.Counter()
    origins = []
    for bp in r.blueprints():
        for ch in r.stream(store=bp).to_chunks():
            rb = ch.to_record_batch()
            for i, f in enumerate(rb.schema):
                md = {k.decode(): v.decode() for k, v in (f.metadata or {}).items()}
                if md.get("rerun:component") == "ViewBlueprint:class_identifier":
                    kinds.update(rb.column(i).to_pylist()[0])
                if md.get("rerun:component") == "ViewBlueprint:space_origin":
                    origins += rb.column(i).to_pylist()[0]
    print(json.dumps({"rows": rows, "timelines": sorted(timelines), "recordings": len(r.recordings()),
                      "blueprints": len(r.blueprints()), "views": kinds, "origins": sorted(origins)}))
    sys.stdout.flush(); os._exit(0)
    """
)


def run(args, ok=True):
    p = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=900)
    if ok and p.returncode != 0:
        pytest.fail(f"{args} exited {p.returncode}\n{p.stdout}\n{p.stderr}")
    return p


def run_json(args):
    return json.loads(run(args).stdout)


@pytest.fixture(scope="module")
def exported(milv_bin: Path, tmp_path_factory):
    need = [milv_bin / "milv-train", milv_bin / "milv-export"]
    if not all(b.is_file() for b in need):
        if os.environ.get("MILV_BIN"):
            pytest.fail(f"{need} not built")
        pytest.skip("milv-train / milv-export not built")
    work = tmp_path_factory.mktemp("export")
    sim, ds, runs = work / "sim", work / "ds", work / "run"
    run([milv_bin / "milv-sim", "gen", "--task", "drawing", "--episodes", "2", "--seed", "3", "--size", "32",
         "--out", sim])
    run_json([milv_bin / "milv-ingest", ds, "--manifest", sim / "manifest.jsonl", "--json"])
    run_json([milv_bin / "milv-align", ds, "--features", "state", "--json"])
    run_json([milv_bin / "milv-train", "cyclegan", ds, "--out", runs, "--tiny", "--size", "32", "--steps", "2",
              "--threads", "1", "--json"])
    run_json([milv_bin / "milv-train", "translate", ds, "--checkpoint", runs / "checkpoints" / "step-00000002",
              "--json"])
    run_json([milv_bin / "milv-score", "run", ds, "--table", "imagined", "--json"])
    run_json([milv_bin / "milv-score", "curate", ds, "--top-fraction", "0.8", "--json"])
    mcap_rep = run_json([milv_bin / "milv-export", "mcap", ds, "-o", work / "all.mcap", "--json"])
    rrd_rep = run_json([milv_bin / "milv-export", "rerun", ds, "--sort", "beta", "-o", work / "all.rrd", "--json"])
    return work, ds, mcap_rep, rrd_rep


def test_mcap_round_trips_bit_for_bit(exported):
    work, ds, rep, _ = exported
    p = subprocess.run([sys.executable, "-c", READ_MCAP, str(work / "all.mcap"), str(ds / "imagined")],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    m = json.loads(p.stdout)
    frames = m["latents"]
    assert frames > 0 and m["actions"] == frames
    assert (m["latent_mismatch"], m["action_mismatch"], m["image_mismatch"]) == (0, 0, 0)
    assert len(m["latent_decoded_shape"]) == 3
    for t in ("/human/image", "/imagined/image", "/robot/image", "/imagined/action", "/robot/action",
              "/quality", "/imagined/latent"):
        assert m["topics"].get(t) == m["stats"][t] > 0, t
    assert m["schemas"]["/human/image"] == "foxglove.CompressedImage"
    assert m["encodings"]["/imagined/latent"] == ["protobuf", "protobuf"]
    assert m["encodings"]["/quality"] == ["jsonschema", "json"]
    assert m["compression"] == ["zstd"] and m["chunks"] > 1 and m["unindexed_chunks"] <= 1
    assert m["streamed"] == sum(m["topics"].values()) == rep["files"][0]["messages"]
    meta = m["metadata"]["milv"]
    assert meta["model_id"] == rep["model_id"] and meta["dataset_version"] == str(rep["version"])
    assert json.loads(meta["command_line"])[1] == "mcap"
    assert m["episode_records"] == rep["files"][0]["episodes"] == 4  # 2 demos + 2 paired clips
    [(name, media, cfg)] = m["attachments"]
    assert (name, media) == ("model_config.json", "application/json") and cfg["image_size"] == 32


def test_rrd_verifies_and_holds_the_entities(exported, milv_bin):
    work, _, mcap_rep, rrd_rep = exported
    rerun_cli = Path(sys.executable).parent / "rerun"
    v = run([rerun_cli, "rrd", "verify", work / "all.rrd"], ok=False)
    assert v.returncode == 0, v.stdout + v.stderr
    p = subprocess.run([sys.executable, "-c", READ_RRD, str(work / "all.rrd")], capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    frames = rrd_rep["logged"]["frames"]
    assert frames == mcap_rep["files"][0]["topics"]["/imagined/image"]
    rows = r["rows"]
    for e in ("/human/image", "/imagined/image", "/latent", "/quality/brenner", "/quality/ssim",
              "/quality/beta", "/quality/weight", "/action/predicted/dx", "/action/predicted/dy"):
        assert rows.get(e) == frames, (e, rows.get(e))
    # Only the paired clips have aligned robot frames: as many as in the MCAP file.
    aligned = mcap_rep["files"][0]["topics"]["/robot/image"]
    assert 0 < aligned < frames
    for e in ("/robot/image", "/action/true/dx", "/action/true/dy"):
        assert rows.get(e) == aligned, (e, rows.get(e))
    assert rows["/episode"] == rrd_rep["logged"]["episodes"] == 4
    assert {"frame", "time"} <= set(r["timelines"])
    assert (r["recordings"], r["blueprints"]) == (1, 1)
    assert r["views"] == {"2D": 4, "TimeSeries": 2, "TextDocument": 1}
    assert "/human" in r["origins"] and "/quality" in r["origins"]


def test_bad_selections_are_clear_errors_and_leave_no_file(exported, milv_bin):
    work, ds, _, _ = exported
    exp = milv_bin / "milv-export"
    cases = [
        (["mcap", ds, "--model-id", "acg-nope", "-o", work / "x.mcap"], "acg-nope"),
        (["mcap", ds, "--episodes", "nope", "-o", work / "x.mcap"], "no episode nope"),
        (["mcap", ds, "-o", work / "missing" / "dir" / "x.mcap"], "missing"),
        (["rerun", ds, "--model-id", "acg-nope", "-o", work / "x.rrd"], "acg-nope"),
    ]
    for args, needle in cases:
        p = run([exp, *args], ok=False)
        assert p.returncode == 1 and needle in p.stderr, (args, p.stderr)
    assert not (work / "x.mcap").exists() and not (work / "x.rrd").exists()
    assert not [f for f in os.listdir(work) if f.endswith(".tmp")]
