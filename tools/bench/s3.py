#!/usr/bin/env python3
"""Object-storage benchmark: the same ingest and score on a local folder and on S3
(SeaweedFS on this machine), and Ray fanning ingest out over 1, 2 and 4 partitions.

    .venv/bin/python tools/bench/s3.py [--episodes 24] [--jobs 2] [--bin target/release]

Data: `milv-sim gen` drawing episodes (128x128 H.264 clips with sidecars), generated into
target/bench-data/s3 and reused. Every configuration starts from an empty dataset; times
are wall-clock seconds of the whole command (start-up, planning, commit included). The
Markdown table goes to stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tools" / "s3"))
from seaweedfs import BUCKET, SeaweedFS  # noqa: E402


def run(argv, env, add_json=True):
    """Runs a command (with --json appended unless told not to); (seconds, its JSON)."""
    t = time.monotonic()
    p = subprocess.run([str(a) for a in argv] + (["--json"] if add_json else []), env=env,
                       capture_output=True, text=True)
    dt = time.monotonic() - t
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, argv))} exited {p.returncode}: {p.stderr[-2000:]}")
    return dt, json.loads(p.stdout[p.stdout.index("{"):])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=24, help="episodes per kind made by milv-sim gen")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--bin", type=Path, default=REPO / "target" / "release")
    ap.add_argument("--repeat", type=int, default=2, help="runs per configuration (best is reported)")
    a = ap.parse_args()
    b = a.bin
    data = REPO / "target" / "bench-data" / "s3" / f"drawing-{a.episodes}"
    if not (data / "manifest.jsonl").is_file():
        shutil.rmtree(data, ignore_errors=True)
        subprocess.run([b / "milv-sim", "gen", "--task", "drawing", "--episodes", str(a.episodes), "--seed", "7",
                        "--out", data], check=True, capture_output=True)
    manifest = data / "manifest.jsonl"
    n_inputs = len(manifest.read_text().splitlines())
    rows = []
    with tempfile.TemporaryDirectory(prefix="milv-bench-s3-") as tmp:
        tmp = Path(tmp)
        (tmp / "weed").mkdir()
        server = SeaweedFS(tmp / "weed")
        try:
            env = server.env()
            env["MILV_INPUT_CACHE"] = str(tmp / "cache")
            server.upload_tree(data, "bench/inputs")
            s3_manifest = f"s3://{BUCKET}/bench/inputs/manifest.jsonl"

            def best(label, make_cmd, fresh):
                times, report = [], None
                for r in range(a.repeat):
                    target = fresh(r)
                    dt, report = run(make_cmd(target), env)
                    times.append(dt)
                rows.append((label, min(times), report))
                return min(times), report

            local = lambda r: tmp / f"local-{len(rows)}-{r}"  # noqa: E731
            remote = lambda r: f"s3://{BUCKET}/bench/ds-{len(rows)}-{r}"  # noqa: E731
            t_il, rep = best("ingest, local folder", lambda d: [b / "milv-ingest", d, "--manifest", manifest,
                                                                "--jobs", a.jobs], local)
            frames = rep["frames"]
            t_is, _ = best("ingest, dataset on S3 (inputs local)",
                           lambda d: [b / "milv-ingest", d, "--manifest", manifest, "--jobs", a.jobs], remote)
            shutil.rmtree(tmp / "cache", ignore_errors=True)
            t_iss, _ = best("ingest, dataset and inputs on S3 (inputs fetched once, then cached)",
                            lambda d: [b / "milv-ingest", d, "--manifest", s3_manifest, "--jobs", a.jobs], remote)
            # Score one ingested copy of each.
            ds_l, ds_s = tmp / "score-local", f"s3://{BUCKET}/bench/score"
            run([b / "milv-ingest", ds_l, "--manifest", manifest], env)
            run([b / "milv-ingest", ds_s, "--manifest", manifest], env)
            t_sl, _ = run([b / "milv-score", "run", ds_l, "--jobs", a.jobs], env)
            t_ss, _ = run([b / "milv-score", "run", ds_s, "--jobs", a.jobs], env)
            # Commit overhead: a one-clip ingest (a version on its own) on each.
            one = sorted(data.glob("*.mp4"))[0]
            t_1l, _ = run([b / "milv-ingest", tmp / "one-local", one], env)
            t_1s, _ = run([b / "milv-ingest", f"s3://{BUCKET}/bench/one", one], env)
            # Ray: 1, 2, 4 partitions of the same ingest.
            ray_rows = []
            for n in (1, 2, 4):
                dt, summary = run([sys.executable, REPO / "tools" / "ray" / "milv_ray.py", "ingest",
                                   f"s3://{BUCKET}/bench/ray-{n}", "--partitions", n, "--bin", b,
                                   "--no-read-back", "--json", "--", "--manifest", s3_manifest, "--jobs", "1"],
                                  env, add_json=False)
                parts = [w["seconds"] for w in summary["workers"]]
                ray_rows.append((n, dt, summary["seconds"], max(parts), sum(parts) / len(parts)))
        finally:
            server.stop()

    print(f"## Object storage (SeaweedFS 4.48 on 127.0.0.1; {n_inputs} clips, {frames} frames, --jobs {a.jobs}, "
          f"best of {a.repeat})\n")
    print("| run | seconds | frames/s | vs local |")
    print("|---|---:|---:|---:|")
    for label, t, base in [("ingest, local folder", t_il, t_il),
                           ("ingest, dataset on S3 (inputs local)", t_is, t_il),
                           ("ingest, dataset and inputs on S3", t_iss, t_il),
                           ("score run, local folder", t_sl, t_sl),
                           ("score run, dataset on S3", t_ss, t_sl),
                           ("one-clip ingest (one version), local", t_1l, t_1l),
                           ("one-clip ingest (one version), S3", t_1s, t_1l)]:
        fps = f"{frames / t:.0f}" if "one-clip" not in label else "-"
        print(f"| {label} | {t:.2f} | {fps} | {t / base:.2f}x |")
    print("\n### Ray launcher (ingest, dataset and inputs on S3, each partition --jobs 1)\n")
    print("| partitions | wall s (incl. Ray start) | launcher s | slowest partition s | mean partition s |")
    print("|---:|---:|---:|---:|---:|")
    for n, dt, ls, mx, mean in ray_rows:
        print(f"| {n} | {dt:.2f} | {ls:.2f} | {mx:.2f} | {mean:.2f} |")
    overhead = t_1s - t_1l
    one_part = ray_rows[0][3]
    print(f"\nA version on S3 costs {t_1s:.2f} s end to end (one-clip ingest: process start, fetch, "
          f"upload, conditional put of the log entry, two Delta commits), {overhead:+.2f} s more than locally.")
    print("Projection for N machines, one partition each, from the 1-partition time and that cost "
          "(worst case: all N commit at once and their commits serialise):")
    print("T(N) ~ T(1 partition) / N + N x (version cost)")
    for n in (4, 16, 64):
        print(f"- N = {n}: ~{one_part / n + n * t_1s:.1f} s (vs {one_part:.1f} s on one machine)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
