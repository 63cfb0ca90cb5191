#!/usr/bin/env python3
"""Alignment accuracy on the issue-19 evaluation sets, per feature kind, with the
proportional warp beside every number: the table behind BENCHMARKS.md's "Beyond
milv-sim" sections, rebuilt from nothing.

Twelve sets: eight of milv-sim (20 loosely paired clips each: drawing seeds 7, 9, 5, 21;
pushing seeds 11, 3, 13, 22) and four of MuJoCo (10 + 10 pairs of two seeds each:
1+2, 3+4, 5+6, 7+8; `tools/mujoco/paired_arms.py`). Features were chosen on the design
sets (`D`: MuJoCo 1+2, 3+4; drawing 7, 9; pushing 11, 3, 13) and are reported on the
held-out ones too (`H`: MuJoCo 5+6, 7+8; drawing 5, 21; pushing 22).

    .venv/bin/python tools/bench/align_accuracy.py                   # auto, all twelve
    .venv/bin/python tools/bench/align_accuracy.py --kinds auto,motion,track --sets p13,mj12
    .venv/bin/python tools/bench/align_accuracy.py --per-pair --json out.json
    .venv/bin/python tools/bench/align_accuracy.py --sets d7 -- --band 0.3   # after --: milv-align's

Sets are generated once under --work (kept: later runs reuse them); each alignment runs
on a fresh copy of its set's dataset, so every run sees the same pinned input. Prints a
Markdown table per kind: mean |frame error|, the proportional warp's, their ratio, the
largest error, untrusted pairs, trusted pairs worse than the proportional warp (the
issue's goal is none), seconds and frames per second; then the totals.
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
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# name: (generator, task or seeds, design set?)
SETS = {
    "mj12": ("mujoco", (1, 2), True),
    "mj34": ("mujoco", (3, 4), True),
    "mj56": ("mujoco", (5, 6), False),
    "mj78": ("mujoco", (7, 8), False),
    "d7": ("drawing", 7, True),
    "d5": ("drawing", 5, False),
    "d9": ("drawing", 9, True),
    "d21": ("drawing", 21, False),
    "p11": ("pushing", 11, True),
    "p3": ("pushing", 3, True),
    "p13": ("pushing", 13, True),
    "p22": ("pushing", 22, False),
}


def run(cmd: list[str], ok: tuple[int, ...] = (0,), **kw) -> subprocess.CompletedProcess:
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if p.returncode not in ok:
        sys.exit(f"{' '.join(map(str, cmd))} failed ({p.returncode}):\n{p.stderr[-2000:]}")
    return p


def built(d: Path) -> bool:
    return (d / ".complete").is_file()


def build(name: str, work: Path, bins: Path, python: str) -> Path:
    """Generates and ingests one set unless it is there already; returns its folder."""
    d = work / name
    # The marker is written last: a set whose generation or ingest failed is rebuilt.
    if built(d):
        return d
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir(parents=True)
    gen, arg, _ = SETS[name]
    if gen == "mujoco":
        env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
        warps = []
        for seed in arg:
            out = d / f"s{seed}"
            run([python, str(ROOT / "tools/mujoco/paired_arms.py"), str(out), "--pairs", "10", "--seed", str(seed)], env=env)
            run([str(bins / "milv-ingest"), str(d / "ds"), "--manifest", str(out / "manifest.jsonl")])
            warps.append((out / "warps.jsonl").read_text())
        (d / "warps.jsonl").write_text("".join(warps))
    else:
        run([str(bins / "milv-sim"), "gen", "--task", gen, "--episodes", "20", "--seed", str(arg), "--out", str(d)])
        run([str(bins / "milv-ingest"), str(d / "ds"), "--manifest", str(d / "manifest.jsonl")])
    (d / ".complete").write_text("")
    return d


def align(d: Path, kind: str, bins: Path, extra: list[str]) -> tuple[dict, float]:
    """Aligns a fresh copy of the set's dataset; returns the JSON report and seconds.
    Exit status 3 (some pairs failed) still reports the others; the failures are counted."""
    with tempfile.TemporaryDirectory(dir=d.parent, prefix=f".{d.name}-") as tmp:
        shutil.copytree(d / "ds", Path(tmp) / "ds")
        t = time.perf_counter()
        p = run([str(bins / "milv-align"), str(Path(tmp) / "ds"), "--features", kind,
                 "--truth", str(d / "warps.jsonl"), "--json", *extra], ok=(0, 3))
        return json.loads(p.stdout), time.perf_counter() - t


def summary(report: dict, seconds: float, where: str) -> dict:
    ps = [p for p in report["pairs"] if p.get("mean_frame_error") is not None]
    if not ps:
        raise SystemExit(f"{where}: no pair has ground truth (is warps.jsonl the set's?)")
    frames = sum(p["human_frames"] + p["robot_frames"] for p in ps)
    mean = sum(p["mean_frame_error"] for p in ps) / len(ps)
    prop = sum(p["proportional_mean_error"] for p in ps) / len(ps)
    return {
        "pairs": len(ps),
        "failed": len(report.get("failed", [])),
        "mean": mean,
        "proportional": prop,
        "ratio": mean / prop if prop else float("nan"),
        "max": max(p["max_frame_error"] for p in ps),
        "untrusted": sorted(p["pair_id"] for p in ps if not p["trusted"]),
        "trusted_worse": sorted(report["trusted_worse_than_proportional"]),
        # Pairs that took the proportional warp (milv-align --proportional-within).
        "proportional_taken": sorted(p["pair_id"] for p in ps if p.get("proportional")),
        "seconds": seconds,
        "frames_per_s": frames / seconds,
        "features_per_pair": dict(sorted(Counter(p["features"] for p in ps).items())),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kinds", default="auto", help="comma-separated --features kinds (default auto)")
    ap.add_argument("--sets", default=",".join(SETS), help=f"comma-separated, of {', '.join(SETS)}")
    ap.add_argument("--work", type=Path, default=ROOT / "target/align-sets", help="where the sets are kept")
    ap.add_argument("--bin", type=Path, default=ROOT / "target/debug", help="folder of milv-align, milv-sim, milv-ingest")
    ap.add_argument("--python", default=str(ROOT / ".venv/bin/python"), help="Python with mujoco (tools/setup.sh)")
    ap.add_argument("--per-pair", action="store_true", help="also print every pair's error beside the baseline")
    ap.add_argument("--json", type=Path, help="write every summary (and with --per-pair the reports) here")
    argv = sys.argv[1:]
    # Everything after the first `--` goes to milv-align untouched.
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    args = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    sets = [s for s in args.sets.split(",") if s]
    kinds = [k for k in args.kinds.split(",") if k]
    if not sets or not kinds:
        ap.error("--sets and --kinds need at least one name each")
    unknown = [s for s in sets if s not in SETS]
    if unknown:
        ap.error(f"unknown sets {unknown}; known: {', '.join(SETS)}")
    to_build = [s for s in sets if not built(args.work / s)]
    needed = ["milv-align"] + (["milv-sim", "milv-ingest"] if to_build else [])
    for b in needed:
        if not (args.bin / b).is_file():
            ap.error(f"{args.bin / b} is missing: build it first (cargo build --bins)")
    if any(SETS[s][0] == "mujoco" for s in to_build):
        if not Path(args.python).is_file():
            ap.error(f"{args.python} is missing: MuJoCo sets need it (tools/setup.sh makes .venv)")
        print(f"MuJoCo renders with MUJOCO_GL={os.environ.get('MUJOCO_GL', 'egl')}", file=sys.stderr)
    folders = {}
    for s in sets:
        t = time.perf_counter()
        folders[s] = build(s, args.work, args.bin, args.python)
        print(f"set {s}: {folders[s]} ({time.perf_counter() - t:.1f} s)", file=sys.stderr)
    out = {}
    for kind in kinds:
        print(f"\n#### `--features {kind}`{' ' + ' '.join(extra) if extra else ''}\n")
        print("| set | | pairs | mean | proportional | × | max | untrusted | trusted, worse than proportional | s | frames/s |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|")
        rows = {}
        for s in sets:
            report, secs = align(folders[s], kind, args.bin, extra)
            r = rows[s] = summary(report, secs, f"{s} ({kind})")
            worse = " ".join(p.rsplit("-", 1)[-1] for p in r["trusted_worse"])
            failed = f" ({r['failed']} failed)" if r["failed"] else ""
            print(f"| {s} | {'D' if SETS[s][2] else 'H'} | {r['pairs']}{failed} | {r['mean']:.2f} | "
                  f"{r['proportional']:.2f} | {r['ratio']:.2f} | {r['max']} | {len(r['untrusted'])} | "
                  f"{len(r['trusted_worse'])} {worse} | {secs:.1f} | {r['frames_per_s']:.0f} |", flush=True)
            if args.per_pair:
                for p in report["pairs"]:
                    flag = "T" if p["trusted"] else "U"
                    kind_used = p["features"] + (">prop" if p.get("proportional") else "")
                    print(f"|   {p['pair_id']} | {kind_used} | | {p['mean_frame_error']:.2f} | "
                          f"{p['proportional_mean_error']:.2f} | | {p['max_frame_error']} | {flag} | "
                          f"cost/dim {p['cost_per_dim']:.5f}, band {p['band']:.1f} | | |")
                r["report"] = report
        worse = sum(len(r["trusted_worse"]) for r in rows.values())
        untr = sum(len(r["untrusted"]) for r in rows.values())
        pairs = sum(r["pairs"] for r in rows.values())
        print(f"\n{kind}: {pairs} pairs, {untr} untrusted, {worse} trusted but worse than proportional; "
              f"worst ratio {max(r['ratio'] for r in rows.values()):.2f}, "
              f"worst mean {max(r['mean'] for r in rows.values()):.2f}")
        taken = sum(len(r["proportional_taken"]) for r in rows.values())
        if taken:
            print(f"{taken} of them took the proportional warp (--proportional-within)")
        out[kind] = rows
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
