"""What the benchmarks that time milv-train beside PyTorch eager share: the common flags,
running our side as a subprocess, and the result row."""

import argparse
import json
import statistics
import subprocess

import torch


def parser(doc: str) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=doc)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--milv-train", default="target/release/milv-train")
    ap.add_argument("--json", help="also write the result row here")
    return ap


def ours(a, subcommand: str, *args: str) -> dict:
    """`milv-train SUBCOMMAND ARGS --steps --warmup --threads --json`, parsed."""
    cmd = [a.milv_train, subcommand, *args, "--steps", str(a.steps), "--warmup", str(a.warmup),
           "--threads", str(a.threads), "--json"]
    return json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)


def row(a, mine: dict, theirs_ms: list, **fields) -> dict:
    t_med = statistics.median(theirs_ms)
    r = dict(fields, threads=a.threads, steps=a.steps, milv_median_ms=mine["median_ms"],
             milv_min_ms=mine["min_ms"], torch_median_ms=t_med, torch_min_ms=min(theirs_ms),
             ratio_median=mine["median_ms"] / t_med, torch_version=torch.__version__)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(r, f, indent=2)
    return r
