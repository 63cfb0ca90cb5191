#!/usr/bin/env python3
"""Generate MILV's bad-input fixtures (plus a few good clips) into a folder.

    python3 tools/make_bad_inputs.py OUT_DIR

Standard library only; needs the ``ffmpeg`` CLI.  Every clip is 32x32, 10 fps,
at most 10 frames, so the whole folder is a few tens of KB.  Output is
deterministic for a given ffmpeg build.

Files written (sidecars sit next to their clip as ``<stem>.json``/``.csv``):

  good_1.mp4 + .json          good human clip, 8 frames, actions only
  good_2.mp4 + .json          good robot clip, 6 frames, actions + states
  empty.mp4 + .json           zero-byte file
  truncated.mp4 + .json       first 40% of a good MP4 (moov atom is at the end, so it is lost)
  notavideo.mp4 + .json       a text file
  noframes.mkv + .json        valid Matroska with an audio stream only (no video stream)
  noframes_video.avi + .json  valid AVI with an H.264 video stream holding zero packets
  short_actions.mp4 + .json   10 frames, 7 action rows
  long_actions.mp4 + .json    10 frames, 13 action rows
  nan_actions.mp4 + .csv      CSV sidecar with a ``nan`` cell
  nan_actions_json.mp4 + .json  JSON sidecar with a bare ``NaN`` literal
  ragged_actions.mp4 + .json  action rows of widths 2 and 3
  mixed_sizes/ + mixed_sizes.json  numbered PNGs, frames 0-2 are 32x32, 3-5 are 48x32
  bad_domain.mp4 + .json      sidecar domain "alien"
  no_sidecar.mp4              no sidecar at all (fails only with --require-actions)
  unreadable.mp4              dangling symlink -> /nonexistent/milv/unreadable.mp4
                              (chmod 000 would not stop root from reading a file)
  duplicate/clip.mp4 + .json, duplicate/manifest.jsonl   the same good clip listed twice
  bad_manifest.jsonl          every top-level fixture above (good and bad), one line each
  expected.json               the outcome each fixture is meant to provoke

All video clips differ in content (the moving box starts elsewhere), so no two
fixtures share a source hash.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

FPS = 10
SIZE = 32


def ffmpeg(*args: str) -> None:
    cmd = ["ffmpeg", "-hide_banner", "-nostdin", "-loglevel", "error", "-y", *args]
    subprocess.run(cmd, check=True)


def source(seed: int, size: str = f"{SIZE}x{SIZE}") -> str:
    """A lavfi test source with a box whose position depends on ``seed``."""
    bx, by = (seed * 6) % 24, (seed * 10) % 24
    return (
        f"testsrc2=size={size}:rate={FPS},"
        f"drawbox=x={bx}:y={by}:w=6:h=6:color=white:t=fill"
    )


BITEXACT = ["-fflags", "+bitexact", "-flags:v", "+bitexact", "-map_metadata", "-1"]
H264 = ["-c:v", "libx264", "-preset", "medium", "-crf", "30", "-threads", "1", "-pix_fmt", "yuv420p"]


def mp4(path: str, seed: int, frames: int) -> None:
    ffmpeg("-f", "lavfi", "-i", source(seed), "-frames:v", str(frames), "-an", *H264, *BITEXACT, path)


def actions(n: int, width: int = 2, seed: int = 0) -> list[list[float]]:
    # Multiples of 0.25: exact in float32, so readers can compare bit-for-bit.
    return [[float(((i * 7 + j * 3 + seed) % 9) - 4) * 0.25 for j in range(width)] for i in range(n)]


def sidecar(path: str, *, domain: str = "human", kind: str = "demo", n: int | None = None,
            acts: list | None = None, states: list | None = None, fps: float | None = None,
            raw_actions_text: str | None = None) -> None:
    episode = {"domain": domain, "kind": kind, "task_id": "fixture/test", "task_family": "fixtures",
               "pair_id": None, "split": "train"}
    if fps is not None:
        episode["fps"] = fps
    doc: dict = {"format": "milv-sidecar/1", "episode": episode, "action_names": ["dx", "dy"]}
    if states is not None:
        doc["state_names"] = ["x", "y"]
    doc["actions"] = acts if acts is not None else actions(n or 0)
    if states is not None:
        doc["states"] = states
    text = json.dumps(doc)
    if raw_actions_text is not None:
        # Splice in text json.dumps would never produce (e.g. a bare NaN literal).
        text = text.replace('"actions": "__RAW__"', f'"actions": {raw_actions_text}')
    with open(path, "w", newline="\n") as f:
        f.write(text + "\n")


def main() -> int:
    if len(sys.argv) != 2:
        print("usage: make_bad_inputs.py OUT_DIR", file=sys.stderr)
        return 2
    if shutil.which("ffmpeg") is None:
        print("make_bad_inputs.py: ffmpeg not found (apt-get install ffmpeg)", file=sys.stderr)
        return 1
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    p = lambda *parts: os.path.join(out, *parts)  # noqa: E731

    manifest: list[dict] = []
    expected: dict[str, dict] = {}

    def add(path: str, side: str | None, outcome: str, why: str) -> None:
        entry = {"path": path}
        if side is not None:
            entry["sidecar"] = side
        manifest.append(entry)
        expected[path] = {"sidecar": side, "outcome": outcome, "why": why}

    # --- good clips -------------------------------------------------------
    mp4(p("good_1.mp4"), 1, 8)
    sidecar(p("good_1.json"), n=8)
    add("good_1.mp4", "good_1.json", "ok", "valid clip, 8 frames, 8 action rows")

    mp4(p("good_2.mp4"), 2, 6)
    sidecar(p("good_2.json"), domain="robot", kind="random", n=6,
            states=[[float(2 * i), 4.0] for i in range(6)])
    add("good_2.mp4", "good_2.json", "ok", "valid robot clip, 6 frames, actions + states")

    # --- broken containers ------------------------------------------------
    open(p("empty.mp4"), "wb").close()
    sidecar(p("empty.json"), n=10)
    add("empty.mp4", "empty.json", "fail", "zero-byte file")

    mp4(p("_whole.mp4"), 3, 10)
    with open(p("_whole.mp4"), "rb") as f:
        data = f.read()
    os.remove(p("_whole.mp4"))
    with open(p("truncated.mp4"), "wb") as f:
        f.write(data[: len(data) * 40 // 100])
    sidecar(p("truncated.json"), n=10)
    add("truncated.mp4", "truncated.json", "fail", "first 40% of an MP4; moov atom missing")

    with open(p("notavideo.mp4"), "w", newline="\n") as f:
        f.write("This is not a video. It is a text file with an .mp4 extension.\n")
    sidecar(p("notavideo.json"), n=10)
    add("notavideo.mp4", "notavideo.json", "fail", "text file, no container")

    ffmpeg("-f", "lavfi", "-i", "sine=frequency=440:sample_rate=8000:duration=0.2",
           "-c:a", "pcm_s16le", "-fflags", "+bitexact", "-flags:a", "+bitexact",
           "-map_metadata", "-1", p("noframes.mkv"))
    sidecar(p("noframes.json"), n=0)
    add("noframes.mkv", "noframes.json", "fail", "audio-only container: no video stream")

    # A real H.264 video stream whose packets are all dropped: the container and
    # codec parameters are valid, but there is not a single frame to decode.
    # (Matroska/MP4 muxers write broken or stream-less files in this case; AVI does not.)
    mp4(p("_src.mp4"), 4, 3)
    ffmpeg("-i", p("_src.mp4"), "-c:v", "copy", "-bsf:v", "noise=dropamount=1", *BITEXACT,
           p("noframes_video.avi"))
    os.remove(p("_src.mp4"))
    sidecar(p("noframes_video.json"), n=0)
    add("noframes_video.avi", "noframes_video.json", "fail", "video stream with zero frames")

    # --- sidecar/frame mismatches -----------------------------------------
    mp4(p("short_actions.mp4"), 5, 10)
    sidecar(p("short_actions.json"), n=7)
    add("short_actions.mp4", "short_actions.json", "fail", "10 frames, 7 action rows")

    mp4(p("long_actions.mp4"), 6, 10)
    sidecar(p("long_actions.json"), n=13)
    add("long_actions.mp4", "long_actions.json", "fail", "10 frames, 13 action rows")

    mp4(p("nan_actions.mp4"), 7, 6)
    rows = actions(6)
    with open(p("nan_actions.csv"), "w", newline="\n") as f:
        f.write("# domain: human\n# kind: demo\n# split: train\n# fps: 10\n")
        f.write("action.dx,action.dy\n")
        for i, (a, b) in enumerate(rows):
            f.write(f"{a!r},{'nan' if i == 3 else repr(b)}\n")
    add("nan_actions.mp4", "nan_actions.csv", "fail", "CSV sidecar row 3 has nan")

    mp4(p("nan_actions_json.mp4"), 8, 6)
    rows_txt = ", ".join("[NaN, 0.5]" if i == 2 else json.dumps(r) for i, r in enumerate(actions(6)))
    sidecar(p("nan_actions_json.json"), acts="__RAW__", raw_actions_text=f"[{rows_txt}]")  # type: ignore[arg-type]
    add("nan_actions_json.mp4", "nan_actions_json.json", "fail", "JSON sidecar row 2 has NaN")

    mp4(p("ragged_actions.mp4"), 9, 6)
    ragged = actions(6)
    ragged[4] = ragged[4] + [1.0]
    sidecar(p("ragged_actions.json"), acts=ragged)
    add("ragged_actions.mp4", "ragged_actions.json", "fail", "row 4 has 3 values, others 2")

    # --- frame folder with two frame sizes --------------------------------
    shutil.rmtree(p("mixed_sizes"), ignore_errors=True)
    os.makedirs(p("mixed_sizes"))
    for i in range(6):
        size = f"{SIZE}x{SIZE}" if i < 3 else f"{SIZE + 16}x{SIZE}"
        ffmpeg("-f", "lavfi", "-i", source(10 + i, size), "-frames:v", "1", "-c:v", "png",
               "-pix_fmt", "rgb24", *BITEXACT, "-update", "1", p("mixed_sizes", f"{i:05d}.png"))
    sidecar(p("mixed_sizes.json"), n=6, fps=FPS)
    add("mixed_sizes", "mixed_sizes.json", "fail",
        "frames 0-2 are 32x32, 3-5 are 48x32 (no --resize)")

    # --- metadata ---------------------------------------------------------
    mp4(p("bad_domain.mp4"), 11, 5)
    sidecar(p("bad_domain.json"), domain="alien", n=5)
    add("bad_domain.mp4", "bad_domain.json", "fail", 'sidecar domain "alien"')

    mp4(p("no_sidecar.mp4"), 12, 5)
    add("no_sidecar.mp4", None, "ok_unless_require_actions",
        "no sidecar: lands without actions, fails with --require-actions")

    # --- unreadable path --------------------------------------------------
    if os.path.lexists(p("unreadable.mp4")):
        os.remove(p("unreadable.mp4"))
    os.symlink("/nonexistent/milv/unreadable.mp4", p("unreadable.mp4"))
    add("unreadable.mp4", None, "fail", "dangling symlink: cannot be opened even as root")

    # --- duplicate listing (own manifest) --------------------------------
    os.makedirs(p("duplicate"), exist_ok=True)
    mp4(p("duplicate", "clip.mp4"), 13, 5)
    sidecar(p("duplicate", "clip.json"), n=5)
    with open(p("duplicate", "manifest.jsonl"), "w", newline="\n") as f:
        for _ in range(2):
            f.write(json.dumps({"path": "clip.mp4", "sidecar": "clip.json"}) + "\n")
    expected["duplicate/manifest.jsonl"] = {
        "sidecar": None, "outcome": "one_ingested_one_failed",
        "why": "the same clip listed twice in one batch: one episode lands, the second is "
               "reported as a duplicate episode (exit code 3)"}

    with open(p("bad_manifest.jsonl"), "w", newline="\n") as f:
        for entry in manifest:
            f.write(json.dumps(entry) + "\n")
    with open(p("expected.json"), "w", newline="\n") as f:
        json.dump(expected, f, indent=2)
        f.write("\n")
    print(f"make_bad_inputs.py: wrote {len(manifest)} fixtures to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
