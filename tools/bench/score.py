#!/usr/bin/env python3
"""Quality-score benchmark: per-frame β (Brenner + gray SSIM with the next frame) on one
thread, same frames, one run each:

  (a) milv-score bench (release build, in-process loop),
  (b) scikit-image 0.26 structural_similarity (+ numpy Brenner),
  (c) OpenCV float64 GaussianBlur SSIM recipe with the same 5-pixel crop (+ numpy Brenner).

    .venv/bin/python tools/bench/score.py [--bin target/release/milv-score]

Each timing is the best of --repeats runs (default 3) of --iters frames. Prints a
Markdown table with µs per frame, ratios, and the largest difference between the
three SSIM values (they must agree to 1e-6).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
import cv2  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402
from skimage import data  # noqa: E402
from skimage.metrics import structural_similarity  # noqa: E402

cv2.setNumThreads(1)


def luma(img):
    f = img.astype(np.float64)
    return 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]


def brenner(y):
    h, w = y.shape
    sh = ((y[:, 2:] - y[:, :-2]) ** 2).sum()
    sv = ((y[2:, :] - y[:-2, :]) ** 2).sum()
    return (sh + sv) / ((h * (w - 2) + (h - 2) * w) * 255.0**2)


def beta_skimage(a, b):
    ya, yb = luma(a), luma(b)
    s = structural_similarity(ya, yb, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255)
    return brenner(ya) * (s + 1) / 2, s


def beta_opencv(a, b):
    x, y = luma(a), luma(b)
    blur = lambda z: cv2.GaussianBlur(z, (11, 11), 1.5, borderType=cv2.BORDER_REFLECT)  # noqa: E731
    mx, my = blur(x), blur(y)
    vx = blur(x * x) - mx * mx
    vy = blur(y * y) - my * my
    vxy = blur(x * y) - mx * my
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    m = ((2 * mx * my + c1) * (2 * vxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    s = m[5:-5, 5:-5].mean()
    return brenner(x) * (s + 1) / 2, s


def timeit(f, a, b, iters, repeats):
    """Best of `repeats` timings of `iters` calls (the minimum is the least noisy)."""
    f(a, b)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(iters):
            r = f(a, b)
        best = min(best, (time.perf_counter() - t0) / iters)
    return best, r[1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/milv-score")
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3, help="best of this many timings, for all three")
    args = ap.parse_args()
    astro = data.astronaut()
    big = np.concatenate([astro[:480], astro[:480, :128]], axis=1)[:480, :640]
    sets = {"128x128": (astro[100:228, 100:228], astro[101:229, 102:230]), "640x480": (big, np.roll(big, 1, axis=1))}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, (a, b) in sets.items():
            a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
            pa, pb = os.path.join(tmp, f"{name}_a.png"), os.path.join(tmp, f"{name}_b.png")
            Image.fromarray(a).save(pa)
            Image.fromarray(b).save(pb)
            iters = args.iters if name == "128x128" else max(args.iters // 10, 5)
            runs = []
            for _ in range(args.repeats):
                out = subprocess.run([args.bin, "bench", pa, pb, "--iters", str(iters), "--json"], check=True, capture_output=True, text=True)
                runs.append(json.loads(out.stdout))
            ours = min(runs, key=lambda r: r["seconds_per_frame"])
            t_sk, s_sk = timeit(beta_skimage, a, b, iters, args.repeats)
            t_cv, s_cv = timeit(beta_opencv, a, b, iters, args.repeats)
            diff = max(abs(ours["ssim"] - s_sk), abs(ours["ssim"] - s_cv))
            rows.append((name, ours["seconds_per_frame"], t_cv, t_sk, diff))
    print("| frames | (a) milv µs/frame | (c) OpenCV-f64 µs | (b) scikit-image µs | (c)/(a) | (b)/(a) | max SSIM diff |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, t, tc, ts, d in rows:
        print(f"| {name} | {t * 1e6:,.1f} | {tc * 1e6:,.1f} | {ts * 1e6:,.1f} | {tc / t:.2f}× | {ts / t:.2f}× | {d:.1e} |")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
