#!/usr/bin/env python3
"""Diagnostic ladder for alignment features on a set made by paired_arms.py: how well
could a feature do if it tracked the end effector perfectly?

Each rung aligns every pair with the same DTW as `milv-align --max-band 0.2` (symmetric2,
a fixed band of 0.2 of the longer clip) on features computed from the sidecars' true end-effector positions, and
prints the mean |frame error| against warps.jsonl beside the proportional warp's:

  prop            stretching one clip onto the other (the baseline)
  progress3d      arc-length progress along the true 3-D path (what no camera sees)
  progress2d      arc-length progress along the path projected into each clip's own
                  camera (summary.json): the best any image-space tip tracker can do
                  with progress alone
  progress2d+H    progress plus image positions, the robot's mapped into the human view
                  by a homography refitted on the current alignment (4 rounds)

  python tools/mujoco/oracle_rungs.py SET [SET ...] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import cv2
import numpy as np


def dtw_symmetric2(a: np.ndarray, b: np.ndarray, band: float = 0.2) -> np.ndarray:
    """Robot frame per human frame (rounded mean over the path), as milv-align reports."""
    n, m = len(a), len(b)
    cost = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    w = max(int(band * max(n, m)), abs(n - m) + 1)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        centre = (i - 1) * (m - 1) / max(n - 1, 1)
        for j in range(max(1, int(centre) - w + 1), min(m, int(centre) + w + 1) + 1):
            c = cost[i - 1, j - 1]
            acc[i, j] = min(acc[i - 1, j] + c, acc[i, j - 1] + c, acc[i - 1, j - 1] + 2 * c)
    i, j, cols = n, m, {}
    while i > 0 and j > 0:
        cols.setdefault(i - 1, []).append(j - 1)
        c = cost[i - 1, j - 1]
        _, i, j = min((acc[i - 1, j - 1] + 2 * c, i - 1, j - 1), (acc[i - 1, j] + c, i - 1, j),
                      (acc[i, j - 1] + c, i, j - 1))
    return np.array([math.floor(np.mean(cols[h]) + 0.5) for h in range(n)])


def progress(xy: np.ndarray) -> np.ndarray:
    p = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    return (p / max(p[-1], 1e-12))[:, None]


def project(x: np.ndarray, cam: dict) -> np.ndarray:
    """Pinhole projection (normalised image coordinates) of a camera looking at its target."""
    pos, target = np.array(cam["pos"]), np.array(cam["target"])
    f = (target - pos) / np.linalg.norm(target - pos)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = x - pos
    z = d @ f
    return np.stack([(d @ r) / z, (d @ u) / z], 1)


def with_homography(ph: np.ndarray, pr: np.ndarray, start: np.ndarray, rounds: int = 4) -> np.ndarray:
    w = start
    scale = ph.std(0).mean()
    for _ in range(rounds):
        h, _ = cv2.findHomography(pr[w].astype(np.float64), ph.astype(np.float64), 0)
        mapped = cv2.perspectiveTransform(pr[None].astype(np.float64), h)[0]
        w = dtw_symmetric2(np.hstack([progress(ph), (ph - ph.mean(0)) / scale]),
                           np.hstack([progress(pr), (mapped - ph.mean(0)) / scale]))
    return w


def rungs(set_dir: Path) -> list[dict]:
    summary = {p["pair_id"]: p for p in json.loads((set_dir / "summary.json").read_text())["pairs"]}
    rows = []
    for line in (set_dir / "warps.jsonl").read_text().splitlines():
        w = json.loads(line)
        pid, truth = w["pair_id"], np.array(w["human_to_robot"])
        idx = pid.rsplit("-", 1)[1]
        ee = {d: np.array(json.loads((set_dir / f"mjreach_{d}_paired_{idx}.json").read_text())["states"])
              for d in ("human", "robot")}
        img = {d: project(ee[d], summary[pid]["cameras"][d]) for d in ee}
        nh, nr = len(ee["human"]), len(ee["robot"])
        err = lambda got: float(np.abs(got - truth).mean())  # noqa: E731
        p2 = dtw_symmetric2(progress(img["human"]), progress(img["robot"]))
        rows.append({
            "pair_id": pid,
            "prop": err(np.floor(np.arange(nh) * (nr - 1) / (nh - 1) + 0.5)),
            "progress3d": err(dtw_symmetric2(progress(ee["human"]), progress(ee["robot"]))),
            "progress2d": err(p2),
            "progress2d+H": err(with_homography(img["human"], img["robot"], p2)),
        })
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sets", type=Path, nargs="+")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = [r for s in a.sets for r in rungs(s)]
    keys = ["prop", "progress3d", "progress2d", "progress2d+H"]
    out = {k: {"mean": float(np.mean([r[k] for r in rows])), "max": float(np.max([r[k] for r in rows]))}
           for k in keys}
    if a.json:
        print(json.dumps({"pairs": rows, "summary": out}, indent=1))
        return
    for k in keys:
        print(f"{k:<14} mean {out[k]['mean']:6.2f}  max {out[k]['max']:6.2f}  "
              f"({out[k]['mean'] / out['prop']['mean']:.2f}x proportional)")


if __name__ == "__main__":
    main()
