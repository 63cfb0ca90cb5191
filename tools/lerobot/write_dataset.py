"""Write a synthetic LeRobot v3.0 dataset with LeRobot's own API (lerobot 0.6.1), offline.

    .venv-lerobot/bin/python tools/lerobot/write_dataset.py --out DIR [--episodes 3] [--frames 20]
        [--frame-step 3] [--size 64x64] [--fps 10] [--cameras observation.images.top,observation.images.wrist]
        [--images] [--vcodec libsvtav1] [--seed 0] [--truth PATH|-|none] [--repo-id local/synthetic]

Runs `LeRobotDataset.create(repo_id, fps, root=DIR, features=..., use_videos=...)`, then
`add_frame` per frame, `save_episode` per episode and `finalize()`, exactly as a LeRobot
recording does. Video (the default) uses LeRobot's default encoder (`RGBEncoderConfig()`:
libsvtav1, yuv420p, g=2, crf=30, preset=12) unless --vcodec is given; --images stores
inline PNG images instead (`use_videos=False`).

Content (deterministic for a given --seed):
  - episode e has `frames + e * frame_step` frames;
  - every camera shows a textured background (different per camera) with a bright square
    that moves >= 3 px per frame, so each frame differs visibly from its neighbours;
  - `action` float32 [4] (names dx, dy, gripper, speed), `observation.state` float32 [3]
    (names x, y, phase); the task text alternates "pick the red cube" / "push the block left".

Ground truth (tasks, lengths, actions, states, names, fps) goes to DIR.truth.json by default
(--truth PATH, `-` for stdout, `none` to skip).  A JSON summary (timings of the LeRobot calls
alone, frame generation excluded) is printed on stdout (stderr when --truth is `-`).

`render_frame()` and `episode_arrays()` are importable, so tests can regenerate the source
frames without reading them back.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

TASKS = ("pick the red cube", "push the block left")
ACTION_NAMES = ["dx", "dy", "gripper", "speed"]
STATE_NAMES = ["x", "y", "phase"]
# Square colours per camera (bright, distinct from every background).
COLOURS = [(255, 40, 40), (40, 255, 60), (60, 90, 255), (255, 230, 30), (255, 60, 255), (30, 240, 240)]


def episode_length(frames: int, frame_step: int, episode: int) -> int:
    return frames + frame_step * episode


def _square(w: int, h: int) -> int:
    return max(4, min(w, h) // 6)


def _bounce(p: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Triangle wave: reflect p into [lo, hi]."""
    span = hi - lo
    if span <= 0:
        return np.full_like(p, lo)
    q = np.mod(p - lo, 2 * span)
    return lo + np.where(q > span, 2 * span - q, q)


def square_positions(length: int, w: int, h: int, episode: int, camera: int, seed: int) -> np.ndarray:
    """Top-left (x, y) of the square per frame, int64 [length, 2]."""
    s = _square(w, h)
    rng = np.random.default_rng([seed, episode, camera, 7])
    vx = int(rng.integers(3, 6)) * (1 if (episode + camera) % 2 == 0 else -1)
    vy = int(rng.integers(2, 5)) * (1 if camera % 2 == 0 else -1)
    x0 = int(rng.integers(0, max(1, w - s)))
    y0 = int(rng.integers(0, max(1, h - s)))
    t = np.arange(length, dtype=np.int64)
    x = _bounce(x0 + vx * t, 0, w - s)
    y = _bounce(y0 + vy * t, 0, h - s)
    return np.stack([x, y], axis=1)


def background(w: int, h: int, camera: int, seed: int) -> np.ndarray:
    """Textured uint8 [h, w, 3] background, different per camera."""
    yy, xx = np.mgrid[0:h, 0:w]
    rng = np.random.default_rng([seed, camera, 11])
    base = rng.integers(40, 120, size=3)
    cell = 4 + 2 * (camera % 3)
    checker = ((xx // cell + yy // cell) % 2) * 30
    grad = (xx * 60 // max(1, w - 1)) + (yy * 40 // max(1, h - 1))
    noise = rng.integers(0, 12, size=(h, w))
    img = np.empty((h, w, 3), dtype=np.int64)
    img[..., 0] = base[0] + checker + grad // 2 + noise
    img[..., 1] = base[1] + (checker if camera % 2 else 30 - checker) + noise
    img[..., 2] = base[2] + grad + noise // 2
    return np.clip(img, 0, 200).astype(np.uint8)


def render_frame(bg: np.ndarray, pos: tuple[int, int], camera: int, frame_index: int) -> np.ndarray:
    """Background + bright square at pos + a frame-index tick bar along the bottom edge."""
    img = bg.copy()
    h, w, _ = img.shape
    s = _square(w, h)
    x, y = int(pos[0]), int(pos[1])
    img[y : y + s, x : x + s] = COLOURS[camera % len(COLOURS)]
    img[y + s // 3 : y + 2 * s // 3, x + s // 3 : x + 2 * s // 3] = 255  # white core
    # A short bar whose position steps with the frame index: a second moving cue.
    bx = (frame_index * 5) % max(1, w - 8)
    img[h - 3 : h, bx : bx + 8] = 230
    return img


def episode_arrays(
    episode: int, length: int, w: int, h: int, n_cameras: int, seed: int
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """(actions float32 [L,4], states float32 [L,3], frames per camera uint8 [L,h,w,3])."""
    pos = [square_positions(length, w, h, episode, c, seed) for c in range(n_cameras)]
    p0 = pos[0].astype(np.float64)
    nxt = np.concatenate([p0[1:], p0[-1:]], axis=0)
    rng = np.random.default_rng([seed, episode, 3])
    d = nxt - p0
    actions = np.empty((length, 4), dtype=np.float32)
    actions[:, 0] = d[:, 0] / 8.0 + rng.normal(0, 0.01, length)
    actions[:, 1] = d[:, 1] / 8.0 + rng.normal(0, 0.01, length)
    actions[:, 2] = (np.arange(length) // 5 + episode) % 2  # gripper open/closed
    actions[:, 3] = np.hypot(d[:, 0], d[:, 1]) / 10.0 + rng.uniform(0, 0.001, length)
    states = np.empty((length, 3), dtype=np.float32)
    states[:, 0] = p0[:, 0] / max(1, w)
    states[:, 1] = p0[:, 1] / max(1, h)
    states[:, 2] = np.arange(length) / max(1, length - 1) + episode
    frames = []
    for c in range(n_cameras):
        bg = background(w, h, c, seed)
        frames.append(np.stack([render_frame(bg, pos[c][i], c, i) for i in range(length)]))
    return actions, states, frames


def features_for(cameras: list[str], w: int, h: int, use_videos: bool) -> dict:
    feats = {}
    for key in cameras:
        feats[key] = {
            "dtype": "video" if use_videos else "image",
            "shape": (h, w, 3),
            "names": ["height", "width", "channels"],
        }
    feats["observation.state"] = {"dtype": "float32", "shape": (len(STATE_NAMES),), "names": list(STATE_NAMES)}
    feats["action"] = {"dtype": "float32", "shape": (len(ACTION_NAMES),), "names": list(ACTION_NAMES)}
    return feats


def parse_size(s: str) -> tuple[int, int]:
    try:
        w, h = s.lower().split("x")
        return int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size expects WxH, got {s!r}") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path, help="dataset root (must not exist)")
    ap.add_argument("--episodes", type=int, default=3)
    ap.add_argument("--frames", type=int, default=20, help="frames of episode 0")
    ap.add_argument("--frame-step", type=int, default=3, help="episode e has FRAMES + e*STEP frames")
    ap.add_argument("--size", type=parse_size, default=(64, 64), help="WxH")
    ap.add_argument("--fps", type=int, default=10)
    ap.add_argument("--cameras", default="observation.images.top", help="comma-separated feature keys")
    ap.add_argument("--images", action="store_true", help="inline PNG images (use_videos=False)")
    ap.add_argument("--vcodec", default=None, help="encoder (default: LeRobot's, libsvtav1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--truth", default=None, help="ground-truth JSON path (default DIR.truth.json; - stdout; none)")
    ap.add_argument("--repo-id", default="local/synthetic")
    args = ap.parse_args(argv)

    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
    t_import = time.perf_counter()
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    rgb_encoder = None
    if args.vcodec:
        from lerobot.configs.video import RGBEncoderConfig

        rgb_encoder = RGBEncoderConfig(vcodec=args.vcodec)
    import_s = time.perf_counter() - t_import

    w, h = args.size
    cameras = [c.strip() for c in args.cameras.split(",") if c.strip()]
    use_videos = not args.images
    out = args.out.resolve()
    if out.exists():
        print(f"write_dataset: {out} exists", file=sys.stderr)
        return 2

    truth = {
        "format": "milv-lerobot-truth/1",
        "root": str(out),
        "repo_id": args.repo_id,
        "fps": args.fps,
        "width": w,
        "height": h,
        "cameras": cameras,
        "use_videos": use_videos,
        "seed": args.seed,
        "action_names": list(ACTION_NAMES),
        "state_names": list(STATE_NAMES),
        "episodes": [],
    }

    lerobot_s = 0.0
    gen_s = 0.0
    t = time.perf_counter()
    ds = LeRobotDataset.create(
        args.repo_id,
        args.fps,
        root=out,
        features=features_for(cameras, w, h, use_videos),
        use_videos=use_videos,
        rgb_encoder=rgb_encoder,
    )
    lerobot_s += time.perf_counter() - t
    total = 0
    for e in range(args.episodes):
        length = episode_length(args.frames, args.frame_step, e)
        task = TASKS[e % len(TASKS)]
        t = time.perf_counter()
        actions, states, frames = episode_arrays(e, length, w, h, len(cameras), args.seed)
        gen_s += time.perf_counter() - t
        t = time.perf_counter()
        for i in range(length):
            frame = {"action": actions[i], "observation.state": states[i], "task": task}
            for c, key in enumerate(cameras):
                frame[key] = frames[c][i]
            ds.add_frame(frame)
        ds.save_episode()
        lerobot_s += time.perf_counter() - t
        total += length
        truth["episodes"].append(
            {
                "episode_index": e,
                "task": task,
                "length": length,
                "actions": actions.astype(float).tolist(),
                "states": states.astype(float).tolist(),
            }
        )
    t = time.perf_counter()
    ds.finalize()
    lerobot_s += time.perf_counter() - t

    summary = {
        "out": str(out),
        "episodes": args.episodes,
        "frames": total,
        "cameras": cameras,
        "use_videos": use_videos,
        "vcodec": (rgb_encoder.vcodec if rgb_encoder else "libsvtav1") if use_videos else None,
        "import_s": round(import_s, 3),
        "generate_s": round(gen_s, 3),
        "write_s": round(lerobot_s, 3),
        "write_fps": round(total / lerobot_s, 1) if lerobot_s > 0 else None,
    }
    if args.truth == "-":
        json.dump(truth, sys.stdout)
        sys.stdout.write("\n")
        print(json.dumps(summary), file=sys.stderr)
    else:
        if args.truth != "none":
            tp = Path(args.truth) if args.truth else out.with_name(out.name + ".truth.json")
            tp.write_text(json.dumps(truth))
            summary["truth"] = str(tp)
        print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
