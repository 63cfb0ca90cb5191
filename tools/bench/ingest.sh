#!/usr/bin/env bash
# MILV ingest benchmark.
#
#   tools/bench/ingest.sh [--quick] [--no-build] [--threads "1 2"] [--encodings "png raw"]
#
# Compares, on the same videos and in one run, frames per second of
#   (a)  milv-ingest (release build)                   --jobs N, --frame-encoding png|raw
#   (b)  ffmpeg -threads N -i X -f null -              decode ceiling, one process per file
#   (b2) PyAV decode-only loop, in-process             decode ceiling without CLI start-up
#   (c)  a straightforward Python ingest (PyAV + Pillow PNG + pyarrow Parquet, zstd)
# on two data sets:
#   clips: 200 H.264 clips, 128x128, 50 frames each (testsrc2, each clip different)
#   long:  one 10-minute 640x480 30 fps H.264 clip
# --quick uses 20 clips and a 30-second long clip.
#
# Also reports milv-ingest's peak RSS (getrusage of the child; no GNU time needed).
# Generated data lives in target/bench-data (reused between runs, never committed).
# The Markdown table goes to stdout and to $OUT (default: bench-results.md).
#
# Environment: MILV_BIN (folder with milv-ingest; skips the cargo build),
#              PYTHON (default .venv/bin/python), BENCH_DATA (default target/bench-data).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
QUICK=0
BUILD=1
THREADS="1 2"
ENCODINGS="png raw"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --quick) QUICK=1 ;;
    --no-build) BUILD=0 ;;
    --threads) THREADS="$2"; shift ;;
    --encodings) ENCODINGS="$2"; shift ;;
    -h|--help) sed -n '2,22p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "ingest.sh: unknown argument $1 (try --help)" >&2; exit 2 ;;
  esac
  shift
done

if [[ $QUICK -eq 1 ]]; then N_CLIPS=20; LONG_SECS=30; MODE=quick; else N_CLIPS=200; LONG_SECS=600; MODE=full; fi
CLIP_FRAMES=50
CLIP_FPS=25
LONG_FPS=30
OUT_MD="${OUT:-bench-results.md}"
DATA="${BENCH_DATA:-$ROOT/target/bench-data}"
PY="${PYTHON:-}"
if [[ -z "$PY" ]]; then
  if [[ -x "$ROOT/.venv/bin/python" ]]; then PY="$ROOT/.venv/bin/python"; else PY=python3; fi
fi
PYB="$ROOT/tools/bench/py_ingest.py"
PNG_LEVEL=1

command -v ffmpeg >/dev/null || { echo "ingest.sh: ffmpeg not found" >&2; exit 1; }
"$PY" -c 'import av, pyarrow, PIL' 2>/dev/null || {
  echo "ingest.sh: $PY lacks av/pyarrow/pillow; run: python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt" >&2
  exit 1
}

if [[ -n "${MILV_BIN:-}" ]]; then
  BIN="$MILV_BIN"
elif [[ $BUILD -eq 1 ]]; then
  (cd "$ROOT" && cargo build --release --bin milv-ingest --bin milv-ds)
  BIN="$ROOT/target/release"
else
  BIN="$ROOT/target/release"
fi
[[ -x "$BIN/milv-ingest" ]] || { echo "ingest.sh: $BIN/milv-ingest not found" >&2; exit 1; }

# ---------------------------------------------------------------------------
# data (cached: regenerated only when the parameters change)
gen_clips() {
  local dir="$DATA/clips-$N_CLIPS" stamp
  stamp="n=$N_CLIPS frames=$CLIP_FRAMES fps=$CLIP_FPS v1"
  if [[ -f "$dir/.stamp" && "$(cat "$dir/.stamp")" == "$stamp" ]]; then return; fi
  echo "bench: generating $N_CLIPS clips of $CLIP_FRAMES frames at 128x128 in $dir" >&2
  rm -rf "$dir"
  mkdir -p "$dir"
  # Each clip starts at a different testsrc2 frame, has its own hue and box position.
  # shellcheck disable=SC2016 # the single-quoted script is expanded by the inner bash
  seq 0 $((N_CLIPS - 1)) |
    xargs -P 2 -I{} bash -c '
    i=$1; dir=$2; frames=$3; fps=$4
    ffmpeg -hide_banner -nostdin -loglevel error -y -f lavfi \
      -i "testsrc2=size=128x128:rate=$fps,trim=start_frame=$(( (i * 13) % 500 )),setpts=PTS-STARTPTS,hue=h=$(( (i * 37) % 360 )),drawbox=x=$(( (i * 7) % 112 )):y=$(( (i * 11) % 112 )):w=16:h=16:color=white:t=fill" \
      -frames:v "$frames" -an -c:v libx264 -preset medium -crf 23 -pix_fmt yuv420p -threads 1 \
      -fflags +bitexact -flags:v +bitexact "$(printf "%s/clip_%04d.mp4" "$dir" "$i")"
  ' _ {} "$dir" "$CLIP_FRAMES" "$CLIP_FPS"
  echo "$stamp" >"$dir/.stamp"
}

gen_long() {
  local file="$DATA/long-${LONG_SECS}s.mp4"
  if [[ -s "$file" ]]; then return; fi
  echo "bench: generating a ${LONG_SECS}s 640x480 ${LONG_FPS} fps clip in $file" >&2
  mkdir -p "$DATA"
  ffmpeg -hide_banner -nostdin -loglevel error -y -f lavfi \
    -i "testsrc2=size=640x480:rate=$LONG_FPS" -t "$LONG_SECS" -an \
    -c:v libx264 -preset veryfast -crf 23 -g 60 -pix_fmt yuv420p \
    -fflags +bitexact -flags:v +bitexact "$file.tmp.mp4"
  mv "$file.tmp.mp4" "$file"
}

gen_clips
gen_long
CLIPS=("$DATA/clips-$N_CLIPS"/clip_*.mp4)
LONG=("$DATA/long-${LONG_SECS}s.mp4")
[[ ${#CLIPS[@]} -eq $N_CLIPS ]] || { echo "ingest.sh: expected $N_CLIPS clips, found ${#CLIPS[@]}" >&2; exit 1; }

# ---------------------------------------------------------------------------
# runs
WORK="$(mktemp -d "${TMPDIR:-/tmp}/milv-bench.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
RESULTS="$WORK/results.jsonl"
"$PY" "$PYB" meta --results "$RESULTS" --mode "$MODE" --milv "$BIN/milv-ingest" --png-level "$PNG_LEVEL"

record() { "$PY" "$PYB" record --results "$RESULTS" "$@"; }

bench_set() {
  local name=$1 label=$2 expect=$3
  shift 3
  local files=("$@") t enc
  echo "bench: $label" >&2
  for t in $THREADS; do
    "$PY" "$PYB" ffmpeg-decode --threads "$t" "${files[@]}" >"$WORK/t.json"
    record --dataset "$name" --label "$label" --tool ffmpeg --threads "$t" --timing "$WORK/t.json" --frames "$expect"

    "$PY" "$PYB" decode --threads "$t" "${files[@]}" >"$WORK/t.json"
    record --dataset "$name" --label "$label" --tool pyav --threads "$t" --timing "$WORK/t.json" --expect-frames "$expect"

    for enc in $ENCODINGS; do
      rm -rf "$WORK/ds"
      "$PY" "$PYB" time --stdout "$WORK/milv.json" -- \
        "$BIN/milv-ingest" "$WORK/ds" "${files[@]}" --domain human --kind demo \
        --jobs "$t" --frame-encoding "$enc" --json >"$WORK/t.json"
      record --dataset "$name" --label "$label" --tool milv --threads "$t" --encoding "$enc" \
        --timing "$WORK/t.json" --milv-output "$WORK/milv.json" --expect-frames "$expect"
      rm -rf "$WORK/ds"

      if [[ "$enc" == png || "$enc" == raw ]]; then
        "$PY" "$PYB" ingest --threads "$t" --encoding "$enc" --png-level "$PNG_LEVEL" \
          --out "$WORK/py.parquet" "${files[@]}" >"$WORK/t.json"
        record --dataset "$name" --label "$label" --tool python --threads "$t" --encoding "$enc" \
          --timing "$WORK/t.json" --expect-frames "$expect"
        rm -f "$WORK/py.parquet"
      fi
    done
  done
}

bench_set clips "${N_CLIPS} × 128x128 H.264 clips (${CLIP_FRAMES} frames)" $((N_CLIPS * CLIP_FRAMES)) "${CLIPS[@]}"
bench_set long "1 × 640x480 H.264 clip (${LONG_SECS} s, ${LONG_FPS} fps)" $((LONG_SECS * LONG_FPS)) "${LONG[@]}"

"$PY" "$PYB" report "$RESULTS" | tee "$OUT_MD"
echo "bench: table written to $OUT_MD" >&2
