#!/usr/bin/env python3
"""Alignment benchmark: banded DTW of two clips of 1,000 frames with 64-d features, the
same band (dtaidistance's `window`) and the same distance (squared Euclidean local cost,
sqrt of the total), in one run:

  (a) milv-align bench (release build; distance only, and with the warping path),
  (b) dtaidistance's C implementation, dtw_ndim.distance(use_c=True).

    .venv/bin/python tools/bench/align.py [--bin target/release/milv-align]

Prints a Markdown table: ms per alignment, ratio, the two distances (must agree), and
the memory the DP needs (ours: O(n·band) bytes with the path).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from dtaidistance import dtw_ndim


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/milv-align")
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--dim", type=int, default=64)
    ap.add_argument("--iters", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(7)
    n = args.frames
    # Two noisy, time-warped copies of one smooth trajectory.
    t = np.linspace(0, 1, n)
    base = np.cumsum(rng.normal(size=(n, args.dim)), axis=0) / np.sqrt(n)
    warp = np.clip(t + 0.05 * np.sin(6 * np.pi * t), 0, 1)
    a = base + 0.05 * rng.normal(size=base.shape)
    b = np.array([base[int(w * (n - 1))] for w in warp]) + 0.05 * rng.normal(size=base.shape)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        pa, pb = os.path.join(tmp, "a.f64"), os.path.join(tmp, "b.f64")
        a.astype("<f8").tofile(pa)
        b.astype("<f8").tofile(pb)
        for frac in (0.05, 0.1, 0.2):
            window = int(frac * n)
            out = subprocess.run([args.bin, "bench", pa, pb, "--dim", str(args.dim), "--window", str(window),
                                  "--iters", str(args.iters)], check=True, capture_output=True, text=True)
            ours = json.loads(out.stdout)
            theirs_d = dtw_ndim.distance(a, b, window=window, use_c=True)
            t0 = time.perf_counter()
            for _ in range(args.iters):
                dtw_ndim.distance(a, b, window=window, use_c=True)
            t_theirs = (time.perf_counter() - t0) / args.iters
            rows.append((frac, window, ours, t_theirs, theirs_d))
    print(f"| band | window | milv distance ms | milv + path ms | dtaidistance C ms | ratio (distance) | ratio (+path) | milv distance | dtaidistance | path memory |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for frac, w, o, tt, td in rows:
        print(f"| {frac:.0%} | {w} | {o['seconds_distance'] * 1e3:.1f} | {o['seconds_with_path'] * 1e3:.1f} | {tt * 1e3:.1f} "
              f"| {tt / o['seconds_distance']:.2f}× | {tt / o['seconds_with_path']:.2f}× | {o['distance']:.6f} | {td:.6f} "
              f"| {o['bytes_with_path'] / 1e6:.2f} MB (n·m would be {n * n / 1e6:.1f} M cells) |")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
