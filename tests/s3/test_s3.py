"""Datasets on object storage: every stage of the demo against `s3://` on a real S3 server
(SeaweedFS), concurrent writers, a crash and its roll-forward, a wrong secret, secrets kept
out of everything stored or printed, python `deltalake` and Ray Data reading the tables
from S3, and the Ray launcher retrying a killed worker."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import BIN, BUCKET, REPO

SAMPLES = REPO / "samples"


@pytest.fixture(scope="session")
def inputs(s3):
    """The bundled samples and the simulated drawing episodes, uploaded to s3://milv/inputs/."""
    s3.upload_tree(SAMPLES, "inputs/samples")
    s3.upload_tree(SAMPLES / "sim" / "drawing", "inputs/drawing")
    return f"s3://{BUCKET}/inputs"


def info(milv, ds):
    return milv.run("milv-ds", "info", ds, json_out=True)


def test_unsupported_locations_are_refused(milv, tmp_path):
    p = milv.run("milv-ds", "info", "gs://bucket/ds", ok=False)
    assert p.returncode != 0
    assert "gs://bucket/ds" in p.stderr and "not supported" in p.stderr, p.stderr
    p = milv.run("milv-ingest", str(tmp_path / "ds"), "ftp://host/clip.mp4", ok=False)
    assert "not supported" in p.stderr, p.stderr


def test_unsafe_commit_settings_are_refused(milv, s3):
    for var, value in [("AWS_S3_ALLOW_UNSAFE_RENAME", "true"), ("AWS_CONDITIONAL_PUT", "disabled"),
                       ("AWS_S3_LOCKING_PROVIDER", "dynamodb")]:
        env = s3.env()
        env[var] = value
        p = subprocess.run([str(BIN / "milv-ingest"), f"s3://{BUCKET}/unsafe", str(SAMPLES / "robot_reach.mp4")],
                           env=env, capture_output=True, text=True, timeout=120)
        assert p.returncode != 0 and var in p.stderr and "refusing" in p.stderr, (var, p.stderr)
    assert s3.objects("unsafe") == [], "nothing may be written under refused settings"


def test_every_stage_round_trips_on_s3(milv, s3, inputs, tmp_path):
    ds = f"s3://{BUCKET}/demo"
    local = tmp_path / "local-ds"
    # Ingest from manifests that live on S3 (their relative paths are fetched too).
    r = milv.run("milv-ingest", ds, "--manifest", f"{inputs}/samples/manifest.jsonl", json_out=True)
    assert r["version"] == 1 and r["failed"] == [], r
    r2 = milv.run("milv-ingest", ds, "--manifest", f"{inputs}/drawing/manifest.jsonl", "--require-actions",
                  json_out=True)
    assert r2["version"] == 2, r2
    again = milv.run("milv-ingest", ds, "--manifest", f"{inputs}/samples/manifest.jsonl", json_out=True)
    assert again["version"] == 2, "re-running an ingest must be a no-op"
    # The same from local files gives the same dataset.
    milv.run("milv-ingest", local, "--manifest", SAMPLES / "manifest.jsonl")
    milv.run("milv-ingest", local, "--manifest", SAMPLES / "sim" / "drawing" / "manifest.jsonl", "--require-actions")
    a, b = info(milv, ds), info(milv, str(local))
    assert (a["episodes"], a["frames"]) == (b["episodes"], b["frames"])
    assert {t: v["rows"] for t, v in a["tables"].items()} == {t: v["rows"] for t, v in b["tables"].items()}
    # Time travel.
    assert info(milv, ds + "@1")["episodes"] < a["episodes"]

    out = tmp_path / "out"
    warps = SAMPLES / "sim" / "drawing" / "warps.jsonl"
    milv.run("milv-align", ds, "--features", "motion", "--truth", warps)
    milv.run("milv-train", "cyclegan", ds, "--out", out / "gan", "--size", "32", "--steps", "2",
             "--alignment", "motion", "--checkpoint-every", "2")
    ckpt = out / "gan" / "checkpoints" / "step-00000002"
    milv.run("milv-train", "translate", ds, "--checkpoint", ckpt)
    milv.run("milv-score", "run", ds)
    milv.run("milv-score", "run", ds, "--table", "imagined")
    milv.run("milv-score", "curate", ds, "--top-fraction", "0.8")
    milv.run("milv-score", "report", ds, "--out", out / "quality")
    milv.run("milv-train", "meta", ds, "--variant", "milv", "--translator", ckpt, "--out", out / "meta",
             "--steps", "2", "--checkpoint-every", "2")
    milv.run("milv-export", "mcap", ds, "--alignment", "motion", "-o", out / "t.mcap")
    milv.run("milv-export", "lerobot", ds, "--table", "imagined", "-o", out / "lerobot")
    assert (out / "t.mcap").stat().st_size > 0 and (out / "lerobot" / "meta" / "info.json").is_file()
    before = info(milv, ds)
    for t in ("scores", "imagined", "curated", "alignments"):
        assert before["tables"][t]["rows"] > 0, (t, before["tables"])
    # Maintenance on S3: compact, vacuum, verify.
    milv.run("milv-ds", "compact", ds)
    milv.run("milv-ds", "vacuum", ds, "--retain-hours", "0")
    v = milv.run("milv-ds", "verify", ds, json_out=True)
    assert v["problems"] == [] and v["files_checked"] > 0, v
    after = info(milv, ds)
    assert {t: x["rows"] for t, x in after["tables"].items()} == {t: x["rows"] for t, x in before["tables"].items()}


def test_four_concurrent_writers_lose_no_commit(milv, s3, inputs):
    ds = f"s3://{BUCKET}/concurrent"
    clips = sorted(p.name for p in (SAMPLES / "sim" / "drawing").glob("*.mp4"))[:8]
    env = s3.env()
    env["MILV_INPUT_CACHE"] = str(milv.cache)
    procs = []
    for w in range(4):
        mine = [f"{inputs}/drawing/{c}" for c in clips[w * 2:(w + 1) * 2]]
        procs.append(subprocess.Popen([str(BIN / "milv-ingest"), ds, *mine, "--json"], env=env,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    reports = []
    for p in procs:
        out, err = p.communicate(timeout=600)
        milv.outputs += [out, err]
        assert p.returncode == 0, err
        reports.append(json.loads(out))
    versions = sorted(r["version"] for r in reports)
    assert versions == [1, 2, 3, 4], versions
    log = milv.run("milv-ds", "log", ds, json_out=True)
    assert sorted(e["version"] for e in log) == [0, 1, 2, 3, 4]
    assert info(milv, ds)["episodes"] == 8
    # Every Delta log holds each dataset version exactly once.
    for table in ("episodes", "frames"):
        seen = []
        for key in s3.objects(f"concurrent/{table}/_delta_log"):
            if key.endswith(".json"):
                for line in s3.read(key).decode().splitlines():
                    action = json.loads(line)
                    if "txn" in action and action["txn"]["appId"] == "milv":
                        seen.append(action["txn"]["version"])
        assert sorted(seen) == [1, 2, 3, 4], (table, seen)
    assert milv.run("milv-ds", "verify", ds, json_out=True)["problems"] == []


def test_sigkill_mid_ingest_then_rerun_resumes_and_completes(milv, s3, inputs):
    ds = f"s3://{BUCKET}/crash"
    milv.run("milv-ingest", ds, str(SAMPLES / "robot_reach.mp4"), "--sidecar", str(SAMPLES / "robot_reach.json"))
    env = s3.env()
    env["MILV_INPUT_CACHE"] = str(milv.cache)
    manifest = f"{inputs}/drawing/manifest.jsonl"
    # Small shards, so files are uploaded (and journaled) while the batch runs.
    args = [str(BIN / "milv-ingest"), ds, "--manifest", manifest, "--jobs", "1", "--shard-mb", "0"]
    p = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while sum(k.endswith(".parquet") for k in s3.objects("crash/frames")) < 1 + 3:
        assert p.poll() is None, "ingest finished before it could be killed"
        assert time.monotonic() < deadline, "no shard uploaded in time"
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.wait()
    # The dataset stays at its last good version, and verifies.
    assert info(milv, ds)["version"] == 1
    assert milv.run("milv-ds", "verify", ds, json_out=True)["problems"] == []
    r = milv.run("milv-ingest", *args[1:], json_out=True)
    n = len((SAMPLES / "sim" / "drawing" / "manifest.jsonl").read_text().splitlines())
    assert r["version"] == 2 and len(r["ingested"]) == n, r
    # Shards the killed run had uploaded were journaled and are reused, not decoded again.
    assert r["resumed"] >= 1, r
    assert info(milv, ds)["episodes"] == n + 1
    # verify also fails on duplicate episode ids
    assert milv.run("milv-ds", "verify", ds, json_out=True)["problems"] == []


def test_wrong_secret_is_a_clear_error_and_no_version(milv, s3, inputs):
    ds = f"s3://{BUCKET}/secret"
    milv.run("milv-ingest", ds, f"{inputs}/drawing/drawing_human_demo_0000.mp4")
    before = info(milv, ds)["version"]
    wrong = "wrong" + s3.secret[5:]
    p = milv.run("milv-ingest", ds, f"{inputs}/drawing/drawing_human_demo_0001.mp4", ok=False, secret=wrong)
    assert p.returncode != 0
    msg = p.stderr
    assert "s3://" in msg and ("403" in msg or "Forbidden" in msg or "SignatureDoesNotMatch" in msg), msg
    assert wrong not in p.stdout + p.stderr
    assert info(milv, ds)["version"] == before


def test_python_deltalake_and_ray_read_the_tables_from_s3(milv, s3, inputs):
    ds = f"s3://{BUCKET}/readers"
    milv.run("milv-ingest", ds, "--manifest", f"{inputs}/drawing/manifest.jsonl")
    i = info(milv, ds)
    code = r"""
import json, sys, os
from deltalake import DeltaTable
import pyarrow.fs as pafs
ds, opts, port = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
out = {}
sources = DeltaTable(f"{ds}/episodes", storage_options=opts).to_pyarrow_table(columns=["source_uri"])
out["sources"] = sources.column("source_uri").to_pylist()
for t in ("episodes", "frames"):
    dt = DeltaTable(f"{ds}/{t}", storage_options=opts)
    out[t] = {"deltalake": dt.to_pyarrow_table(columns=["episode_id"]).num_rows, "version": dt.version()}
import ray
ray.init(num_cpus=1, include_dashboard=False, _node_ip_address="127.0.0.1", logging_level="ERROR")
s3 = pafs.S3FileSystem(access_key=opts["AWS_ACCESS_KEY_ID"], secret_key=opts["AWS_SECRET_ACCESS_KEY"],
                       region="us-east-1", endpoint_override=f"127.0.0.1:{port}", scheme="http")
for t in ("episodes", "frames"):
    # read_delta hands the filesystem table-relative paths: root it at the table.
    fs = pafs.SubTreeFileSystem(f"{ds}/{t}".removeprefix("s3://"), s3)
    out[t]["ray"] = ray.data.read_delta(f"{ds}/{t}", storage_options=opts, filesystem=fs,
                                        columns=["episode_id"]).count()
print(json.dumps(out))
"""
    p = subprocess.run([sys.executable, "-c", code, ds, json.dumps(s3.storage_options()), str(s3.port)],
                       env=s3.env(), capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    got = json.loads(p.stdout.strip().splitlines()[-1])
    # Source URIs name the S3 objects, not the local copies ingest read.
    assert got["sources"] and all(u.startswith(f"s3://{BUCKET}/inputs/") for u in got["sources"]), got["sources"]
    for t in ("episodes", "frames"):
        assert got[t]["deltalake"] == i["tables"][t]["rows"] == got[t]["ray"], (t, got, i["tables"][t])


def test_ray_launcher_retries_a_killed_worker(milv, s3, inputs):
    ds = f"s3://{BUCKET}/ray"
    env = s3.env()
    env["MILV_INPUT_CACHE"] = str(milv.cache)
    p = subprocess.run([sys.executable, str(REPO / "tools" / "ray" / "milv_ray.py"), "ingest", ds,
                        "--partitions", "4", "--fail-once", "1", "--bin", str(BIN), "--json", "--",
                        "--manifest", f"{inputs}/drawing/manifest.jsonl"],
                       env=env, capture_output=True, text=True, timeout=900)
    milv.outputs += [p.stdout, p.stderr]
    assert p.returncode == 0, p.stderr[-3000:]
    summary = json.loads(p.stdout[p.stdout.index("{"):])
    assert sorted(w["partition"] for w in summary["workers"]) == [0, 1, 2, 3]
    # Partition 1's first attempt was killed mid-run; what came back is Ray's retry.
    assert [w["partition"] for w in summary["workers"] if w["retried"]] == [1], summary["workers"]
    assert summary["workers"][1]["first_attempt_killed_running"] is True, summary["workers"]
    n = len((SAMPLES / "sim" / "drawing" / "manifest.jsonl").read_text().splitlines())
    assert info(milv, ds)["episodes"] == n
    rb = summary["read_back"]
    assert rb["tables"]["episodes"]["rows"] == n
    assert rb["tables"]["frames"]["rows"] == rb["frames"]
    assert milv.run("milv-ds", "verify", ds, json_out=True)["problems"] == []


def test_zz_secrets_never_stored_or_printed(milv, s3):
    """Runs last (by name): every object any test wrote, and every output, without the secret."""
    keys = s3.objects("")
    assert keys, "the tests wrote nothing?"
    for key in keys:
        if key.endswith((".json", ".jsonl", ".crc", ".checkpoint")) or "/_milv/" in key:
            assert s3.secret.encode() not in s3.read(key), key
    for text in milv.outputs:
        assert s3.secret not in text
