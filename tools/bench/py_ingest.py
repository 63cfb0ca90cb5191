#!/usr/bin/env python3
"""Python side of the ingest benchmark (driven by tools/bench/ingest.sh).

Subcommands, each printing one JSON object on stdout:

  ingest --threads N --encoding png|raw --out FILE.parquet VIDEO...
      The baseline: a straightforward Python ingest.  PyAV decodes each video to
      RGB24, every frame becomes a row (episode_id, frame_index, timestamp_ns,
      image) with `image` a PNG (Pillow, --png-level, default 1 = fast) or the
      raw RGB24 bytes, written with pyarrow to one zstd-compressed Parquet file
      in row groups of --row-group frames.  N > 1: N worker threads take whole
      videos (one decoder thread each); for a single video the decoder gets N
      threads instead.  -> {"wall_s", "frames", "bytes"}
  decode --threads N VIDEO...
      Decode-only loop in-process with PyAV (no start-up cost per file, no RGB
      conversion, like `-f null`), same threading rule as ingest.
      -> {"wall_s", "frames"}
  ffmpeg-decode --threads N VIDEO...
      `ffmpeg -threads N -i VIDEO -f null -` per file, one after another.
      -> {"wall_s", "files"}
  time [--stdout FILE] -- CMD ARG...
      Run CMD, measuring wall time and the peak RSS of the child (from
      getrusage(RUSAGE_CHILDREN), so no GNU time is needed).
      -> {"wall_s", "max_rss_kb", "rc"}
  record --results FILE --dataset D --tool T --threads N [--encoding E] ...
      Append one result line (JSON) to FILE, merging a `time`/`decode`/...
      answer (--timing) and, for milv-ingest, its --json output (--milv-output).
  meta --results FILE --mode M --milv BIN
      Append a line describing the machine and tool versions.
  report RESULTS.jsonl
      Turn the result lines written by ingest.sh into a Markdown table.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import resource
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor


# --------------------------------------------------------------------------
# decoding


def _open_video(path: str, threads: int):
    import av

    container = av.open(path)
    stream = container.streams.video[0]
    stream.codec_context.thread_count = threads
    stream.thread_type = "AUTO" if threads > 1 else "SLICE"
    return container, stream


def _decode_count(path: str, threads: int) -> int:
    container, stream = _open_video(path, threads)
    try:
        n = 0
        for _frame in container.decode(stream):
            n += 1
        return n
    finally:
        container.close()


def _plan(files: list[str], threads: int) -> tuple[int, int]:
    """(worker threads over files, decoder threads per file)."""
    if len(files) == 1 or threads <= 1:
        return 1, max(threads, 1)
    return threads, 1


def cmd_decode(args) -> dict:
    workers, dec_threads = _plan(args.files, args.threads)
    t0 = time.perf_counter()
    if workers == 1:
        frames = sum(_decode_count(f, dec_threads) for f in args.files)
    else:
        with ThreadPoolExecutor(workers) as pool:
            frames = sum(pool.map(lambda f: _decode_count(f, dec_threads), args.files))
    return {"wall_s": time.perf_counter() - t0, "frames": frames}


def cmd_ffmpeg_decode(args) -> dict:
    t0 = time.perf_counter()
    for f in args.files:
        subprocess.run(["ffmpeg", "-hide_banner", "-nostdin", "-loglevel", "error",
                        "-threads", str(args.threads), "-i", f,
                        "-threads", str(args.threads), "-f", "null", "-"], check=True)
    return {"wall_s": time.perf_counter() - t0, "files": len(args.files)}


# --------------------------------------------------------------------------
# the Python ingest baseline


def _episode_id(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:32]


def cmd_ingest(args) -> dict:
    import pyarrow as pa
    import pyarrow.parquet as pq
    from PIL import Image

    schema = pa.schema([
        ("episode_id", pa.string()),
        ("frame_index", pa.int32()),
        ("timestamp_ns", pa.int64()),
        ("image", pa.binary()),
    ])
    lock = threading.Lock()
    writer = pq.ParquetWriter(args.out, schema, compression="zstd")

    def flush(rows: dict) -> None:
        if rows["image"]:
            batch = pa.table(rows, schema=schema)
            with lock:
                writer.write_table(batch)
            for v in rows.values():
                v.clear()

    def encode(frame) -> bytes:
        rgb = frame.to_ndarray(format="rgb24")
        if args.encoding == "raw":
            return rgb.tobytes()
        buf = io.BytesIO()
        Image.fromarray(rgb, "RGB").save(buf, format="PNG", compress_level=args.png_level)
        return buf.getvalue()

    def ingest_one(path: str, dec_threads: int) -> int:
        eid = _episode_id(path)
        container, stream = _open_video(path, dec_threads)
        rows: dict = {"episode_id": [], "frame_index": [], "timestamp_ns": [], "image": []}
        n = 0
        tb = stream.time_base
        try:
            for frame in container.decode(stream):
                pts = frame.pts if frame.pts is not None else 0
                rows["episode_id"].append(eid)
                rows["frame_index"].append(n)
                rows["timestamp_ns"].append(int(pts * tb.numerator * 1_000_000_000 // tb.denominator))
                rows["image"].append(encode(frame))
                n += 1
                if len(rows["image"]) >= args.row_group:
                    flush(rows)
            flush(rows)
        finally:
            container.close()
        return n

    workers, dec_threads = _plan(args.files, args.threads)
    t0 = time.perf_counter()
    try:
        if workers == 1:
            frames = sum(ingest_one(f, dec_threads) for f in args.files)
        else:
            with ThreadPoolExecutor(workers) as pool:
                frames = sum(pool.map(lambda f: ingest_one(f, dec_threads), args.files))
    finally:
        writer.close()
    wall = time.perf_counter() - t0
    return {"wall_s": wall, "frames": frames, "bytes": os.path.getsize(args.out)}


# --------------------------------------------------------------------------
# timing a child process


def cmd_time(args) -> dict:
    cmd = args.cmd[1:] if args.cmd and args.cmd[0] == "--" else args.cmd
    if not cmd:
        raise SystemExit("time: no command given")
    out = open(args.stdout, "wb") if args.stdout else subprocess.DEVNULL
    try:
        t0 = time.perf_counter()
        rc = subprocess.run(cmd, stdout=out).returncode
        wall = time.perf_counter() - t0
    finally:
        if args.stdout:
            out.close()
    # ru_maxrss is in KiB on Linux: the largest resident set of any waited-for child.
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return {"wall_s": wall, "max_rss_kb": rss, "rc": rc}


# --------------------------------------------------------------------------
# recording results


def cmd_record(args) -> None:
    rec: dict = {"kind": "result", "dataset": args.dataset, "label": args.label or args.dataset,
                 "tool": args.tool, "threads": args.threads, "encoding": args.encoding}
    notes = []
    if args.timing:
        with open(args.timing) as f:
            rec.update(json.load(f))
    if args.frames is not None and rec.get("frames") is None:
        rec["frames"] = args.frames
    if rec.get("rc") not in (None, 0):
        notes.append(f"exit code {rec['rc']}")
    if args.milv_output:
        try:
            with open(args.milv_output) as f:
                out = json.load(f)
            rec["frames"] = out.get("frames")
            if out.get("failed"):
                notes.append(f"{len(out['failed'])} inputs failed: {out['failed'][0]}")
        except (OSError, ValueError) as e:
            notes.append(f"no JSON report from milv-ingest ({e})")
            rec["frames"] = None
    if args.expect_frames is not None and rec.get("frames") not in (None, args.expect_frames):
        notes.append(f"{rec.get('frames')} frames, expected {args.expect_frames}")
    if rec.get("rc") not in (None, 0) or (args.milv_output and rec.get("frames") is None):
        rec["frames"] = None  # do not report a rate for a failed run
    if notes:
        rec["note"] = "; ".join(notes)
        print(f"bench: {args.dataset}/{args.tool}/{args.encoding}/{args.threads}: {rec['note']}", file=sys.stderr)
    with open(args.results, "a") as f:
        f.write(json.dumps(rec) + "\n")
    fps = rec["frames"] / rec["wall_s"] if rec.get("frames") and rec.get("wall_s") else None
    extra = f", peak RSS {rec['max_rss_kb'] / 1024:.0f} MiB" if rec.get("max_rss_kb") else ""
    print(f"  {args.tool:<7} {args.encoding or '-':<4} threads={args.threads}: "
          f"{'failed' if fps is None else f'{fps:,.0f} frames/s'} ({rec.get('wall_s', 0):.2f} s{extra})",
          file=sys.stderr)


def cmd_meta(args) -> None:
    import datetime
    import platform

    def first_line(cmd):
        try:
            out = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
            return (out.stdout or out.stderr).strip().splitlines()[0]
        except (OSError, IndexError, subprocess.SubprocessError):
            return "unknown"

    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), cpu)
    except OSError:
        pass
    try:
        import av
        pyav = f"{av.__version__} (libavcodec {'.'.join(map(str, av.library_versions['libavcodec']))})"
    except Exception:  # noqa: BLE001
        pyav = "unknown"
    rec = {"kind": "meta", "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "mode": args.mode, "cpu": cpu, "cores": os.cpu_count(),
           "ffmpeg": first_line(["ffmpeg", "-hide_banner", "-version"]),
           "pyav": pyav, "milv_ingest": first_line([args.milv, "--version"]),
           "python_png_level": args.png_level}
    with open(args.results, "a") as f:
        f.write(json.dumps(rec) + "\n")


# --------------------------------------------------------------------------
# report


def _fmt_fps(v):
    return "—" if v is None else f"{v:,.0f}"


def _ratio(a, b):
    return "—" if a is None or b in (None, 0) else f"{a / b:.2f}×"


def cmd_report(args) -> str:
    rows = [json.loads(ln) for ln in open(args.results) if ln.strip()]
    meta = next((r for r in rows if r.get("kind") == "meta"), {})
    res: dict = {}
    for r in rows:
        if r.get("kind") == "meta":
            continue
        key = (r["dataset"], r["threads"], r["tool"], r.get("encoding"))
        res[key] = r

    def fps(dataset, threads, tool, enc=None):
        r = res.get((dataset, threads, tool, enc))
        if not r or not r.get("frames") or not r.get("wall_s"):
            return None
        return r["frames"] / r["wall_s"]

    lines = []
    lines.append("# MILV ingest benchmark")
    lines.append("")
    for k in ("date", "mode", "cpu", "cores", "ffmpeg", "pyav", "milv_ingest", "python_png_level"):
        if k in meta:
            lines.append(f"- **{k}**: {meta[k]}")
    lines.append("")
    lines.append("Frames per second (higher is better), wall clock, same input files for every column.")
    lines.append("")
    lines.append("- (a) `milv-ingest --jobs N --frame-encoding E` into a fresh dataset (Delta commit included)")
    lines.append("- (b) `ffmpeg -threads N -i X -f null -`, one process per file: the decode ceiling "
                 "(pays the CLI's start-up for every file)")
    lines.append("- (b2) PyAV decode-only loop in one process, no RGB conversion (N threads over files, "
                 "or N decoder threads for a single file)")
    lines.append("- (c) straightforward Python ingest: PyAV + Pillow PNG (or raw bytes) + pyarrow Parquet, zstd")
    lines.append("")
    lines.append("| data set | frames | encoding | threads | (a) milv-ingest | (b) ffmpeg | (b2) PyAV decode "
                 "| (c) Python ingest | (a)/(b) | (a)/(b2) | (a)/(c) | milv peak RSS |")
    lines.append("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    datasets = sorted({k[0] for k in res}, key=lambda d: (d != "clips", d))
    threads_all = sorted({k[1] for k in res})
    encs = [e for e in ("png", "raw", "jpeg") if any(k[3] == e for k in res)]
    for d in datasets:
        for enc in encs:
            for t in threads_all:
                a = fps(d, t, "milv", enc)
                b = fps(d, t, "ffmpeg")
                b2 = fps(d, t, "pyav")
                c = fps(d, t, "python", enc)
                ra = res.get((d, t, "milv", enc), {})
                frames = ra.get("frames") or res.get((d, t, "pyav", None), {}).get("frames")
                rss = ra.get("max_rss_kb")
                rss_s = "—" if not rss else f"{rss / 1024:,.0f} MiB"
                label = res.get((d, t, "pyav", None), {}).get("label", d)
                lines.append(f"| {label} | {frames or '—'} | {enc} | {t} | {_fmt_fps(a)} | {_fmt_fps(b)} | "
                             f"{_fmt_fps(b2)} | {_fmt_fps(c)} | {_ratio(a, b)} | {_ratio(a, b2)} | "
                             f"{_ratio(a, c)} | {rss_s} |")
    problems = [r for r in res.values() if r.get("note")]
    if problems:
        lines.append("")
        lines.append("Notes:")
        for r in problems:
            lines.append(f"- {r['dataset']} / {r['tool']} / {r.get('encoding') or '-'} / "
                         f"{r['threads']} threads: {r['note']}")
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd_name", required=True)

    p = sub.add_parser("ingest")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--encoding", choices=["png", "raw"], default="png")
    p.add_argument("--png-level", type=int, default=1)
    p.add_argument("--row-group", type=int, default=256)
    p.add_argument("--out", required=True)
    p.add_argument("files", nargs="+")

    p = sub.add_parser("decode")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("files", nargs="+")

    p = sub.add_parser("ffmpeg-decode")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("files", nargs="+")

    p = sub.add_parser("time")
    p.add_argument("--stdout")
    p.add_argument("cmd", nargs=argparse.REMAINDER)

    p = sub.add_parser("record")
    p.add_argument("--results", required=True)
    p.add_argument("--dataset", required=True)
    p.add_argument("--label")
    p.add_argument("--tool", required=True)
    p.add_argument("--threads", type=int, required=True)
    p.add_argument("--encoding")
    p.add_argument("--timing")
    p.add_argument("--milv-output")
    p.add_argument("--frames", type=int)
    p.add_argument("--expect-frames", type=int)

    p = sub.add_parser("meta")
    p.add_argument("--results", required=True)
    p.add_argument("--mode", required=True)
    p.add_argument("--milv", required=True)
    p.add_argument("--png-level", type=int, default=1)

    p = sub.add_parser("report")
    p.add_argument("results")

    args = ap.parse_args()
    if args.cmd_name == "report":
        sys.stdout.write(cmd_report(args))
        return 0
    if args.cmd_name == "record":
        cmd_record(args)
        return 0
    if args.cmd_name == "meta":
        cmd_meta(args)
        return 0
    fn = {"ingest": cmd_ingest, "decode": cmd_decode, "ffmpeg-decode": cmd_ffmpeg_decode,
          "time": cmd_time}[args.cmd_name]
    print(json.dumps(fn(args)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
