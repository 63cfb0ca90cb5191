"""LeRobot 0.6.1's own Python on the data MILV's LeRobot import/export processes, and (optionally) MILV.

    .venv-lerobot/bin/python tools/bench/lerobot.py [--episodes 10] [--frames 200] [--size 128x128]
        [--fps 30] [--backends pyav] [--milv-bin target/release] [--jobs N] [--work DIR] [--keep]

LeRobot side (each step a separate process, timed, peak RSS from /usr/bin/time -v, or from
getrusage(RUSAGE_CHILDREN) of a wrapper process when GNU time is missing):
  write_video   tools/lerobot/write_dataset.py: LeRobotDataset.create + add_frame/save_episode
                per episode + finalize(), one camera, LeRobot's default AV1 (libsvtav1) encoder
  write_images  the same with inline PNG images (use_videos=False)
  read_video    LeRobotDataset(root=..., video_backend=B) and ds[i] for every i (decodes video)
  read_images   the same on the images dataset
"api_s" times the LeRobot calls alone (no interpreter start, imports or frame synthesis);
"wall_s" is the whole process. frames/s are reported for both.

MILV side (with --milv-bin; binaries milv-ingest and milv-export), on the same data:
  import_video / import_images  milv-ingest DS --from-lerobot <the LeRobot dataset> --json
                                (compared with LeRobot's read_video / read_images)
  export_video / export_images  milv-export lerobot DS -o OUT --video|--images --json
                                (compared with LeRobot's write_video / write_images)
Ratios are MILV frames/s over LeRobot frames/s (> 1: MILV faster), against LeRobot's api_s
(generous to LeRobot) and wall_s. A JSON report goes to stdout; progress to stderr.
Runs offline (HF_HUB_OFFLINE=1, a temporary HF_HOME / HF_LEROBOT_HOME).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# This file is named lerobot.py: keep its own folder off sys.path so `import lerobot` finds LeRobot.
if sys.path and Path(sys.path[0] or ".").resolve() == Path(__file__).resolve().parent:
    sys.path.pop(0)

ROOT = Path(__file__).resolve().parents[2]
WRITER = ROOT / "tools" / "lerobot" / "write_dataset.py"
GNU_TIME = "/usr/bin/time"

RUSAGE_WRAPPER = (
    "import resource, subprocess, sys\n"
    "rc = subprocess.call(sys.argv[1:])\n"
    "sys.stderr.write('\\nMaximum resident set size (kbytes): %d\\n' % "
    "resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
    "sys.exit(rc)\n"
)


def log(msg: str) -> None:
    print(f"bench-lerobot: {msg}", file=sys.stderr, flush=True)


def measured(cmd: list, env: dict) -> dict:
    """Runs cmd; returns wall_s, peak_rss_mb, stdout, stderr (fails loudly on a non-zero exit)."""
    cmd = [str(c) for c in cmd]
    if os.access(GNU_TIME, os.X_OK):
        full = [GNU_TIME, "-v", *cmd]
    else:
        full = [sys.executable, "-c", RUSAGE_WRAPPER, *cmd]
    t = time.perf_counter()
    p = subprocess.run(full, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        sys.stderr.write(p.stdout + p.stderr)
        raise SystemExit(f"bench-lerobot: {' '.join(cmd)} exited {p.returncode}")
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    return {"wall_s": round(wall, 3), "peak_rss_mb": round(int(m.group(1)) / 1024, 1) if m else None,
            "stdout": p.stdout, "stderr": p.stderr}


def last_json(text: str) -> dict:
    """The JSON document a command printed: all of stdout (MILV pretty-prints), or else its
    last line that is one (the LeRobot-side scripts print progress before it)."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        pass
    for line in reversed(text.strip().splitlines()):
        line = line.strip()
        if line.startswith("{"):
            return json.loads(line)
    raise ValueError(f"no JSON line in output:\n{text[-2000:]}")


def fps(frames: int, seconds: float | None) -> float | None:
    return round(frames / seconds, 1) if seconds else None


# --------------------------------------------------------------------------
# the read step, run in its own process: `lerobot.py --_read DIR --backend B`


def read_main(root: str, backend: str) -> int:
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
    t0 = time.perf_counter()
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    t1 = time.perf_counter()
    ds = LeRobotDataset("local/bench", root=root, video_backend=backend)
    t2 = time.perf_counter()
    n = 0
    for i in range(len(ds)):
        item = ds[i]
        n += 1
    t3 = time.perf_counter()
    assert n == ds.meta.total_frames and "action" in item
    print(json.dumps({"frames": n, "import_s": round(t1 - t0, 3), "load_s": round(t2 - t1, 3),
                      "iterate_s": round(t3 - t2, 3), "api_s": round(t3 - t1, 3)}))
    return 0


# --------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--frames", type=int, default=200, help="frames per episode")
    ap.add_argument("--size", default="128x128", help="WxH")
    ap.add_argument("--fps", type=int, default=30)
    ap.add_argument("--backends", default="pyav", help="LeRobot video backends to read with: pyav,torchcodec")
    ap.add_argument("--milv-bin", type=Path, help="folder with milv-ingest and milv-export: also run MILV")
    ap.add_argument("--jobs", type=int, help="milv-ingest --jobs")
    ap.add_argument("--work", type=Path, help="work folder (default: a temporary one)")
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    ap.add_argument("--_read", help=argparse.SUPPRESS)
    ap.add_argument("--backend", default="pyav", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args._read:
        return read_main(args._read, args.backend)

    work = args.work or Path(tempfile.mkdtemp(prefix="milv-bench-lerobot-"))
    work.mkdir(parents=True, exist_ok=True)
    hf = work / "hf"
    env = dict(os.environ, HF_HUB_OFFLINE="1", HF_DATASETS_OFFLINE="1", HF_HUB_DISABLE_TELEMETRY="1",
               HF_HOME=str(hf / "home"), HF_LEROBOT_HOME=str(hf / "lerobot"),
               HF_DATASETS_CACHE=str(hf / "datasets"))
    py = sys.executable
    n_frames = args.episodes * args.frames
    report: dict = {
        "params": {"episodes": args.episodes, "frames_per_episode": args.frames, "size": args.size,
                   "fps": args.fps, "cameras": 1, "total_frames": n_frames},
        "env": _env_info(),
        "lerobot": {},
    }
    try:
        # ---- LeRobot writes
        data = {}
        for kind in ("video", "images"):
            out = work / f"lerobot_{kind}"
            shutil.rmtree(out, ignore_errors=True)
            log(f"LeRobot write {kind}: {args.episodes} x {args.frames} frames at {args.size}")
            cmd = [py, WRITER, "--out", out, "--episodes", args.episodes, "--frames", args.frames,
                   "--frame-step", 0, "--size", args.size, "--fps", args.fps, "--truth", "none",
                   "--cameras", "observation.images.cam"]
            if kind == "images":
                cmd.append("--images")
            r = measured(cmd, env)
            s = last_json(r["stdout"])
            assert s["frames"] == n_frames, s
            report["lerobot"][f"write_{kind}"] = {
                "frames": n_frames, "api_s": s["write_s"], "fps_api": fps(n_frames, s["write_s"]),
                "wall_s": r["wall_s"], "fps_wall": fps(n_frames, r["wall_s"]), "peak_rss_mb": r["peak_rss_mb"],
                "size_mb": round(_du(out) / 2**20, 2),
            }
            data[kind] = out
        # ---- LeRobot reads
        for kind in ("video", "images"):
            backends = [b.strip() for b in args.backends.split(",")] if kind == "video" else ["pyav"]
            for b in backends:
                log(f"LeRobot read {kind} ({b}): every item")
                r = measured([py, __file__, "--_read", data[kind], "--backend", b], env)
                s = last_json(r["stdout"])
                key = f"read_{kind}" + ("" if b == "pyav" or kind == "images" else f"_{b}")
                report["lerobot"][key] = {
                    "frames": s["frames"], "backend": b if kind == "video" else None,
                    "api_s": s["api_s"], "fps_api": fps(s["frames"], s["api_s"]),
                    "wall_s": r["wall_s"], "fps_wall": fps(s["frames"], r["wall_s"]),
                    "load_s": s["load_s"], "peak_rss_mb": r["peak_rss_mb"],
                }
        # ---- MILV
        if args.milv_bin:
            report["milv"] = _milv(args, work, data, env, n_frames)
            report["ratios"] = _ratios(report)
    finally:
        if not args.keep and not args.work:
            shutil.rmtree(work, ignore_errors=True)
        elif args.keep or args.work:
            report["work"] = str(work)
    json.dump(report, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


def _milv(args, work: Path, data: dict, env: dict, n_frames: int) -> dict:
    b = args.milv_bin.resolve()
    for name in ("milv-ingest", "milv-export"):
        if not os.access(b / name, os.X_OK):
            raise SystemExit(f"bench-lerobot: {b / name} not found")
    out: dict = {}
    for kind in ("video", "images"):
        ds = work / f"milv_{kind}"
        shutil.rmtree(ds, ignore_errors=True)
        cmd = [b / "milv-ingest", ds, "--from-lerobot", data[kind], "--json"]
        if kind == "video":
            cmd += ["--camera", "observation.images.cam"]
        if args.jobs:
            cmd += ["--jobs", args.jobs]
        log(f"milv-ingest --from-lerobot ({kind})")
        r = measured(cmd, env)
        rep = last_json(r["stdout"])
        got = sum(e["n_frames"] for e in rep.get("ingested", []))
        assert got == n_frames and not rep.get("failed"), rep
        out[f"import_{kind}"] = {"frames": got, "wall_s": r["wall_s"], "fps_wall": fps(got, r["wall_s"]),
                                 "peak_rss_mb": r["peak_rss_mb"]}
    for kind in ("video", "images"):
        dest = work / f"milv_export_{kind}"
        shutil.rmtree(dest, ignore_errors=True)
        log(f"milv-export lerobot --{kind}")
        r = measured([b / "milv-export", "lerobot", work / "milv_video", "-o", dest, f"--{kind}", "--json"], env)
        out[f"export_{kind}"] = {"frames": n_frames, "wall_s": r["wall_s"], "fps_wall": fps(n_frames, r["wall_s"]),
                                 "peak_rss_mb": r["peak_rss_mb"], "size_mb": round(_du(dest) / 2**20, 2)}
    return out


def _ratios(report: dict) -> dict:
    lr, mv = report["lerobot"], report["milv"]
    pairs = {"import_video": "read_video", "import_images": "read_images",
             "export_video": "write_video", "export_images": "write_images"}
    out = {}
    for m, l in pairs.items():
        if m in mv and l in lr:
            out[m] = {
                "vs": f"lerobot {l}",
                "speed_vs_lerobot_api": round(mv[m]["fps_wall"] / lr[l]["fps_api"], 2),
                "speed_vs_lerobot_wall": round(mv[m]["fps_wall"] / lr[l]["fps_wall"], 2),
                "peak_rss_ratio": (round(mv[m]["peak_rss_mb"] / lr[l]["peak_rss_mb"], 3)
                                   if mv[m]["peak_rss_mb"] and lr[l]["peak_rss_mb"] else None),
            }
    return out


def _du(path: Path) -> int:
    return sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())


def _env_info() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    vers = {}
    for p in ("lerobot", "torch", "av", "datasets", "torchcodec"):
        try:
            vers[p] = version(p)
        except PackageNotFoundError:
            vers[p] = None
    return {"python": platform.python_version(), "cpus": os.cpu_count(),
            "loadavg_at_start": [round(x, 2) for x in os.getloadavg()], "packages": vers}


if __name__ == "__main__":
    sys.exit(main())
