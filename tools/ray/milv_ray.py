#!/usr/bin/env python3
"""Fan a MILV stage out over a Ray cluster as `--partition i/n` workers.

Every worker is the stage's own binary run with `--partition i/n`: it reads the pinned
dataset version, processes its share, and commits its own version to the shared dataset
(a folder on shared storage, or `s3://bucket/prefix`). Ray only schedules the processes
and retries a task whose worker died or failed; MILV's version log makes a retried
partition land exactly once (episode ids are content hashes, runs are idempotent). When
all partitions are in, the tables are read back with `ray.data.read_delta` at the Delta
versions the final dataset version pins (time travel).

    # one machine (2 CPUs, nothing listens beyond 127.0.0.1)
    tools/ray/milv_ray.py ingest s3://milv/ds --partitions 4 -- --manifest s3://milv/in/manifest.jsonl
    tools/ray/milv_ray.py score s3://milv/ds --partitions 4
    tools/ray/milv_ray.py translate s3://milv/ds --partitions 4 -- --checkpoint out/ckpt
    tools/ray/milv_ray.py align s3://milv/ds --partitions 4 -- --features motion

    # a multi-node cluster (`ray start --head` on one node, `ray start --address=HEAD:6379`
    # on the others, the MILV binaries at the same path on every node, AWS_* set on all)
    tools/ray/milv_ray.py score s3://bucket/ds --partitions 64 --address auto --bin /opt/milv/bin

Environment: the standard AWS variables configure S3 for the workers (Ray passes this
process's environment to them); RAY_USAGE_STATS_ENABLED=0 is always set.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("AWS_EC2_METADATA_DISABLED", "true")

import ray  # noqa: E402

REPO = Path(__file__).resolve().parents[2]

# stage -> (the command before DATASET, whether it reports with --json)
STAGES = {
    "ingest": (["milv-ingest"], True),
    "score": (["milv-score", "run"], True),
    "translate": (["milv-train", "translate"], False),
    "align": (["milv-align"], True),
}

# Variables a worker needs; everything else of this process's environment is left out so
# that a cluster's workers do not inherit, say, a developer's shell.
PASSED_ENV = ("AWS_", "MILV_", "RUST_LOG", "PATH", "HOME", "TMPDIR", "LD_LIBRARY_PATH", "LIBTORCH")


def worker_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k.startswith(PASSED_ENV)}


@ray.remote(num_cpus=1)
def run_partition(cmd: list[str], env: dict[str, str], part: int, fail_once: str | None) -> dict:
    """One `--partition i/n` worker. Raises on failure so that Ray retries it."""
    start = time.monotonic()
    # A marker left by a killed first attempt: this run is Ray's retry of it.
    retried = bool(fail_once) and Path(fail_once).exists()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if fail_once and not retried:
        # Fault injection for tests: the first attempt of this partition dies mid-run
        # (its MILV process is SIGKILLed, then the Ray worker process itself exits). It is
        # stopped at once, so a fast worker cannot finish before the kill (a timed kill
        # missed workers that finished in under 0.3 s).
        proc.send_signal(signal.SIGSTOP)
        # Whether the kill really hit a running worker (it had not finished yet).
        Path(fail_once).write_text(json.dumps({"killed_running": proc.poll() is None}))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        os._exit(1)
    out, err = proc.communicate()
    seconds = time.monotonic() - start
    # Exit code 3: some inputs were bad (reported, skipped); the rest landed. Not retried.
    if proc.returncode not in (0, 3):
        raise RuntimeError(f"partition {part}: {' '.join(cmd)} exited {proc.returncode}: {err.strip()[-2000:]}")
    try:
        report = json.loads(out) if out.strip() else None
    except json.JSONDecodeError:
        report = None
    killed_running = None
    if retried:
        killed_running = json.loads(Path(fail_once).read_text())["killed_running"]
        Path(fail_once).unlink(missing_ok=True)
    return {"partition": part, "exit": proc.returncode, "seconds": round(seconds, 3), "retried": retried,
            "first_attempt_killed_running": killed_running, "report": report}


def storage_options() -> dict[str, str]:
    keys = ("AWS_ENDPOINT_URL", "AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_SESSION_TOKEN", "AWS_REGION", "AWS_ALLOW_HTTP")
    return {k: os.environ[k] for k in keys if k in os.environ}


def table_filesystem(table_url: str):
    """pyarrow's S3 filesystem for the endpoint in AWS_ENDPOINT_URL (Ray's default one
    would go to AWS itself), rooted at the table (`read_delta` hands it table-relative
    paths); None for local tables."""
    if not table_url.startswith("s3://"):
        return None
    from pyarrow import fs

    endpoint = os.environ.get("AWS_ENDPOINT_URL")
    kw = {}
    if endpoint:
        scheme, _, host = endpoint.partition("://")
        kw = {"endpoint_override": host, "scheme": scheme}
    return fs.SubTreeFileSystem(table_url.removeprefix("s3://"), fs.S3FileSystem(
        access_key=os.environ.get("AWS_ACCESS_KEY_ID"),
        secret_key=os.environ.get("AWS_SECRET_ACCESS_KEY"),
        session_token=os.environ.get("AWS_SESSION_TOKEN"),
        region=os.environ.get("AWS_REGION", "us-east-1"),
        **kw,
    ))


def read_back(bin_dir: Path, dataset: str) -> dict:
    """Row counts of every table at the dataset's latest version, read by Ray Data
    (`read_delta` at the Delta version that dataset version pins)."""
    info = json.loads(subprocess.run([str(bin_dir / "milv-ds"), "info", dataset, "--json"], check=True,
                                     capture_output=True, text=True, env=worker_env()).stdout)
    opts = storage_options() if dataset.startswith("s3://") else None
    ctx = ray.data.DataContext.get_current()
    ctx.enable_progress_bars = False
    logging.getLogger("ray.data").setLevel(logging.WARNING)
    tables = {}
    for name, t in info["tables"].items():
        if t.get("delta_version") is None:
            continue
        url = dataset.rstrip("/") + "/" + name
        if not dataset.startswith("s3://"):
            url = str(Path(url).resolve())
        ds = ray.data.read_delta(url, version=t["delta_version"], storage_options=opts,
                                 filesystem=table_filesystem(url),
                                 columns=["episode_id"] if name != "models" else None)
        tables[name] = {"delta_version": t["delta_version"], "rows": ds.count(), "expected_rows": t["rows"]}
    return {"version": info["version"], "episodes": info["episodes"], "frames": info["frames"], "tables": tables}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("stage", choices=sorted(STAGES))
    p.add_argument("dataset", help="dataset folder (on storage every node sees) or s3://bucket/prefix")
    p.add_argument("--partitions", type=int, required=True, help="number of --partition i/n workers")
    p.add_argument("--address", default=None,
                   help="Ray cluster address (`auto` for a running cluster); default: a local Ray bound to 127.0.0.1")
    p.add_argument("--num-cpus", type=int, default=2, help="CPUs of the local Ray (ignored with --address)")
    p.add_argument("--retries", type=int, default=3, help="retries of a failed or lost partition")
    p.add_argument("--bin", type=Path, default=REPO / "target" / "debug", help="folder of the MILV binaries")
    p.add_argument("--fail-once", type=int, default=None, metavar="I",
                   help="testing: kill partition I's first attempt mid-run (worker and process)")
    p.add_argument("--no-read-back", action="store_true", help="skip reading the tables back with Ray Data")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.usage = "%(prog)s STAGE DATASET --partitions N [options] [-- STAGE ARGS...]"
    argv = sys.argv[1:] if argv is None else argv
    cut = argv.index("--") if "--" in argv else len(argv)
    a = p.parse_args(argv[:cut])
    extra = argv[cut + 1:]
    if a.partitions < 1:
        p.error("--partitions must be at least 1")

    if a.address:
        ray.init(address=a.address, logging_level="WARNING")
    else:
        ray.init(num_cpus=a.num_cpus, include_dashboard=False, _node_ip_address="127.0.0.1",
                 logging_level="WARNING", configure_logging=False)
    env = worker_env()
    started = time.monotonic()
    marker_dir = Path(os.environ.get("TMPDIR", "/tmp"))
    refs = []
    for i in range(a.partitions):
        (tool, *sub), json_flag = STAGES[a.stage]
        cmd = [str(a.bin / tool), *sub, a.dataset, *extra, "--partition", f"{i}/{a.partitions}"]
        cmd += ["--json"] if json_flag else []
        fail = str(marker_dir / f"milv-ray-fail-{os.getpid()}-{i}") if a.fail_once == i else None
        refs.append(run_partition.options(max_retries=a.retries, retry_exceptions=True).remote(cmd, env, i, fail))
    results = ray.get(refs)
    summary = {
        "stage": a.stage,
        "dataset": a.dataset,
        "partitions": a.partitions,
        "seconds": round(time.monotonic() - started, 3),
        "workers": results,
    }
    if not a.no_read_back:
        summary["read_back"] = read_back(a.bin, a.dataset)
    ray.shutdown()
    if a.json:
        print(json.dumps(summary, indent=2))
    else:
        for r in results:
            print(f"partition {r['partition']}: exit {r['exit']} in {r['seconds']} s")
        if "read_back" in summary:
            rb = summary["read_back"]
            print(f"{a.dataset}@{rb['version']}: {rb['episodes']} episodes, {rb['frames']} frames")
            for name, t in rb["tables"].items():
                print(f"  {name}: {t['rows']} rows (Delta version {t['delta_version']}) via ray.data.read_delta")
    return 0


if __name__ == "__main__":
    sys.exit(main())
