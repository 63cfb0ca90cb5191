#!/usr/bin/env bash
# Generate MILV's bundled sample clips, their action sidecars and a manifest.
#
#   tools/make_samples.sh [OUT_DIR]        (default: samples/ at the repository root)
#
# Output (all tiny, 10 fps, deterministic for a given ffmpeg build):
#   human_reach.mp4   H.264 / MP4      96x96 24 frames  sidecar .json (paired with robot_reach)
#   human_pour.webm   VP9 / WebM       64x64 20 frames  sidecar .json
#   human_stack.mkv   AV1 (SVT) / MKV  96x96 26 frames  sidecar .json
#   human_wipe.avi    MJPEG / AVI      64x64 22 frames  sidecar .json
#   robot_reach.mp4   H.264 / MP4      64x64 24 frames  sidecar .json (paired with human_reach)
#   robot_push.webm   VP9 / WebM       96x96 30 frames  sidecar .csv
#   robot_draw.mkv    MPEG-4 / MKV     64x64 28 frames  sidecar .json
#   robot_wipe.avi    MJPEG / AVI      96x96 20 frames  sidecar .json
#   robot_sim_frames/ numbered PNGs    64x64 20 frames  sidecar robot_sim_frames.json (fps 10)
#   manifest.jsonl    one line per episode: path, sidecar, domain, split
#
# Every clip shows a white box that moves by exactly the sidecar's actions:
# states[i] = [x, y] of the box's top-left corner in frame i and
# actions[i] = states[i+1] - states[i] (the last action is [0, 0]).  The walk
# comes from a fixed-seed generator, so reruns give the same bytes.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="${1:-$ROOT/samples}"
PYTHON="${PYTHON:-python3}"
FPS=10

command -v ffmpeg >/dev/null || { echo "make_samples.sh: ffmpeg not found (apt-get install ffmpeg)" >&2; exit 1; }
command -v "$PYTHON" >/dev/null || { echo "make_samples.sh: $PYTHON not found" >&2; exit 1; }

mkdir -p "$OUT"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

# Deterministic trajectories, sidecars, manifest and ffmpeg sendcmd scripts.
# One line per clip on stdout: name ext size frames lavfi-source box-size
"$PYTHON" - "$OUT" "$WORK" "$FPS" >"$WORK/clips.txt" <<'PY'
import json, os, random, sys

out, work, fps = sys.argv[1], sys.argv[2], int(sys.argv[3])

# name, ext, size, frames, lavfi source, seed, sidecar ext, episode metadata
CLIPS = [
    ("human_reach", "mp4", 96, 24, "testsrc2", 101, "json",
     dict(domain="human", kind="paired", task_id="reach/red_box", task_family="reaching",
          pair_id="pair-reach-01", split="train")),
    ("human_pour", "webm", 64, 20, "mandelbrot", 102, "json",
     dict(domain="human", kind="demo", task_id="pour/cup", task_family="pouring",
          pair_id=None, split="train")),
    ("human_stack", "mkv", 96, 26, "smptebars", 103, "json",
     dict(domain="human", kind="demo", task_id="stack/blocks", task_family="stacking",
          pair_id=None, split="val")),
    ("human_wipe", "avi", 64, 22, "rgbtestsrc", 104, "json",
     dict(domain="human", kind="demo", task_id="wipe/table", task_family="wiping",
          pair_id=None, split="test")),
    ("robot_reach", "mp4", 64, 24, "smptehdbars", 201, "json",
     dict(domain="robot", kind="paired", task_id="reach/red_box", task_family="reaching",
          pair_id="pair-reach-01", split="train")),
    ("robot_push", "webm", 96, 30, "testsrc2", 202, "csv",
     dict(domain="robot", kind="random", task_id="push/block", task_family="pushing",
          pair_id=None, split="train")),
    ("robot_draw", "mkv", 64, 28, "testsrc", 203, "json",
     dict(domain="robot", kind="demo", task_id="draw/circle", task_family="drawing",
          pair_id=None, split="val")),
    ("robot_wipe", "avi", 96, 20, "mandelbrot", 204, "json",
     dict(domain="robot", kind="demo", task_id="wipe/table", task_family="wiping",
          pair_id=None, split="test")),
    ("robot_sim_frames", "png", 64, 20, "testsrc2", 205, "json",
     dict(domain="robot", kind="random", task_id="push/block", task_family="pushing",
          pair_id=None, split="train")),
]


def walk(seed, size, frames, box):
    """Random walk of the box's top-left corner, in even pixels, inside the frame."""
    rng = random.Random(seed)
    hi = size - box
    x, y = rng.randrange(0, hi // 2) * 2, rng.randrange(0, hi // 2) * 2
    states = []
    for _ in range(frames):
        states.append([float(x), float(y)])
        x = min(max(x + rng.choice((-4, -2, 0, 2, 4)), 0), hi)
        y = min(max(y + rng.choice((-4, -2, 0, 2, 4)), 0), hi)
    actions = [[b[0] - a[0], b[1] - a[1]] for a, b in zip(states, states[1:])]
    actions.append([0.0, 0.0])
    return actions, states


def fmt(v):
    return repr(float(v))


manifest = []
for name, ext, size, frames, src, seed, side_ext, meta in CLIPS:
    box = size // 8
    actions, states = walk(seed, size, frames, box)
    robot = meta["domain"] == "robot"
    episode = dict(meta, fps=fps)
    side = f"{name}.{side_ext}"
    if side_ext == "json":
        doc = {"format": "milv-sidecar/1", "episode": episode, "action_names": ["dx", "dy"]}
        if robot:
            doc["state_names"] = ["x", "y"]
        doc["actions"] = actions
        if robot:
            doc["states"] = states
        text = json.dumps(doc, separators=(", ", ": ")) + "\n"
    else:
        lines = [f"# {k}: {v}" for k, v in episode.items() if v is not None]
        cols = ["action.dx", "action.dy"] + (["state.x", "state.y"] if robot else [])
        lines.append(",".join(cols))
        for a, s in zip(actions, states):
            lines.append(",".join(fmt(v) for v in (a + s if robot else a)))
        text = "\n".join(lines) + "\n"
    with open(os.path.join(out, side), "w", newline="\n") as f:
        f.write(text)

    # sendcmd script: move the box just before each frame's timestamp.
    with open(os.path.join(work, f"{name}.cmd"), "w") as f:
        for i, (x, y) in enumerate(states):
            t = max(i / fps - 0.5 / fps, 0.0)
            f.write(f"{t:.3f} drawbox@box x {int(x)}, drawbox@box y {int(y)};\n")

    path = f"{name}/" if ext == "png" else f"{name}.{ext}"
    manifest.append({"path": path.rstrip("/"), "sidecar": side,
                     "domain": meta["domain"], "split": meta["split"]})
    print(name, ext, size, frames, src, box)

with open(os.path.join(out, "manifest.jsonl"), "w", newline="\n") as f:
    for m in manifest:
        f.write(json.dumps(m) + "\n")
PY

# Encoder settings per container. Single-threaded encoders keep output bit-exact.
codec_args() {
  case "$1" in
    mp4)  echo "-c:v libx264 -preset medium -crf 26 -g 12 -threads 1 -pix_fmt yuv420p -bsf:v filter_units=remove_types=6 -movflags +faststart" ;;
    webm) echo "-c:v libvpx-vp9 -b:v 0 -crf 40 -deadline good -cpu-used 4 -g 12 -threads 1 -row-mt 0 -pix_fmt yuv420p" ;;
    # MJPEG is full-range: FFmpeg 5.1's encoder refuses plain yuv420p without -strict unofficial.
    avi)  echo "-c:v mjpeg -q:v 8 -pix_fmt yuvj420p" ;;
    *)    echo "make_samples.sh: unknown container $1" >&2; return 1 ;;
  esac
}

while read -r -u 3 name ext size frames src box; do
  filter="${src}=size=${size}x${size}:rate=${FPS},sendcmd=f=${WORK}/${name}.cmd,drawbox@box=x=0:y=0:w=${box}:h=${box}:color=white:t=fill"
  common=(-hide_banner -nostdin -loglevel error -y -f lavfi -i "$filter" -frames:v "$frames" -an
          -fflags +bitexact -flags:v +bitexact -map_metadata -1)
  if [[ "$ext" == png ]]; then
    rm -rf "${OUT:?}/${name}"
    mkdir -p "$OUT/$name"
    ffmpeg "${common[@]}" -c:v png -pix_fmt rgb24 -start_number 0 "$OUT/$name/%05d.png"
    continue
  fi
  if [[ "$ext" == mkv && "$name" == human_* ]]; then
    # AV1 via SVT-AV1 (SVT_LOG=1 silences its banner); one thread, fixed preset.
    SVT_LOG=1 ffmpeg "${common[@]}" -c:v libsvtav1 -preset 8 -crf 45 -g 12 \
      -svtav1-params lp=1 -pix_fmt yuv420p "$OUT/$name.$ext"
  elif [[ "$ext" == mkv ]]; then
    # MPEG-4 Part 2 in Matroska.
    ffmpeg "${common[@]}" -c:v mpeg4 -q:v 6 -g 12 -bf 2 -threads 1 -pix_fmt yuv420p "$OUT/$name.$ext"
  else
    read -r -a args <<<"$(codec_args "$ext")"
    ffmpeg "${common[@]}" "${args[@]}" "$OUT/$name.$ext"
  fi
done 3<"$WORK/clips.txt"

echo "make_samples.sh: wrote $(wc -l <"$OUT/manifest.jsonl") episodes to $OUT ($(du -sh "$OUT" | cut -f1))"
