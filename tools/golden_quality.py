#!/usr/bin/env python3
"""Golden values for milv-quality, computed by independent references.

    .venv/bin/python tools/golden_quality.py crates/milv-quality/tests/golden

SSIM comes from scikit-image 0.26 (`structural_similarity(..., gaussian_weights=True,
sigma=1.5, use_sample_covariance=False, data_range=255)`), gray on BT.601 luma in float64
and rgb with channel_axis=-1. Brenner is the spec's formula in numpy. Inputs are crops of
scikit-image's bundled photographs plus synthetic edge cases, written as PNG next to
golden.json.
"""

import json
import os
import sys

import numpy as np
from PIL import Image
from skimage import data
from skimage.metrics import structural_similarity


def luma(img):
    f = img.astype(np.float64)
    return 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]


def brenner(img):
    y = luma(img)
    h, w = y.shape
    sh = float(((y[:, 2:] - y[:, :-2]) ** 2).sum())
    sv = float(((y[2:, :] - y[:-2, :]) ** 2).sum())
    nh, nv = h * (w - 2), (h - 2) * w
    return {"raw": sh + sv, "normalized": (sh + sv) / ((nh + nv) * 255.0**2), "horizontal": sh / (nh * 255.0**2)}


def ssim(a, b, rgb):
    kw = dict(gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255)
    if rgb:
        return float(structural_similarity(a.astype(np.float64), b.astype(np.float64), channel_axis=-1, **kw))
    return float(structural_similarity(luma(a), luma(b), **kw))


def main(out):
    os.makedirs(out, exist_ok=True)
    rng = np.random.default_rng(0)
    astro = data.astronaut()
    coffee = data.coffee()
    cat = data.chelsea()
    stripes = np.zeros((16, 16, 3), np.uint8)
    stripes[:, ::2] = 255
    pairs = {
        # Real photographs: a crop and the same crop one pixel later (adjacent frames).
        "astronaut_64": (astro[100:164, 200:264], astro[101:165, 201:265]),
        "coffee_96x128": (coffee[150:246, 250:378], coffee[152:248, 250:378]),
        "chelsea_40x48": (cat[100:140, 150:198], cat[100:140, 153:201]),
        "astronaut_128": (astro[0:128, 0:128], astro[3:131, 2:130]),
        # Edge cases.
        "constant": (np.full((16, 16, 3), 90, np.uint8), np.full((16, 16, 3), 90, np.uint8)),
        "identical": (astro[300:320, 300:330], astro[300:320, 300:330]),
        "inverted_stripes": (stripes, 255 - stripes),
        "random_13x17": (rng.integers(0, 256, (13, 17, 3), dtype=np.uint8), rng.integers(0, 256, (13, 17, 3), dtype=np.uint8)),
        "min_11x11": (cat[0:11, 0:11], cat[5:16, 5:16]),
    }
    golden = []
    for name, (a, b) in pairs.items():
        a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
        Image.fromarray(a).save(os.path.join(out, f"{name}_a.png"))
        Image.fromarray(b).save(os.path.join(out, f"{name}_b.png"))
        golden.append({
            "name": name, "width": int(a.shape[1]), "height": int(a.shape[0]),
            "brenner_a": brenner(a), "ssim_gray": ssim(a, b, False), "ssim_rgb": ssim(a, b, True),
        })
    with open(os.path.join(out, "golden.json"), "w") as f:
        json.dump({"generator": "tools/golden_quality.py", "skimage": __import__("skimage").__version__, "cases": golden}, f, indent=1)
    print(f"{len(golden)} cases -> {out}")


if __name__ == "__main__":
    main(sys.argv[1])
