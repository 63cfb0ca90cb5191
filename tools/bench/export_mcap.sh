#!/usr/bin/env bash
# MCAP export throughput: milv-mcap (the library behind `milv-export mcap`, release build)
# against tools/bench/export_mcap.py (the `mcap` Python writer, same messages), and a raw
# copy of the same number of bytes (the disk ceiling), in one run.
#
# usage: tools/bench/export_mcap.sh [--episodes N] [--repeats R] [--work DIR]
# The dataset: N simulated drawing tasks at 128x128, ingested, aligned (motion), translated
# by an A-CycleGAN at the paper's widths after one training step (the weights do not
# matter here; latents are 64x32x32 f16 as in real runs), scored and curated.
set -euo pipefail
cd "$(dirname "$0")/../.."
# Absolute paths: cargo runs benches from the package folder.
episodes=10 repeats=3 work=$PWD/target/bench-mcap
while [ $# -gt 0 ]; do
  case $1 in
    --episodes) episodes=$2; shift 2 ;;
    --repeats) repeats=$2; shift 2 ;;
    --work) work=$(realpath -m "$2"); shift 2 ;;
    *) echo "unknown argument $1" >&2; exit 2 ;;
  esac
done
B=target/debug
ds=$work/ds
if [ ! -d "$ds" ]; then
  mkdir -p "$work"
  "$B/milv-sim" gen --task drawing --episodes "$episodes" --seed 31 --out "$work/sim" > /dev/null
  "$B/milv-ingest" "$ds" --manifest "$work/sim/manifest.jsonl" > /dev/null
  "$B/milv-align" "$ds" --features motion > /dev/null
  "$B/milv-train" cyclegan "$ds" --out "$work/acg" --size 128 --steps 1 --checkpoint-every 1 > /dev/null
  "$B/milv-train" translate "$ds" --checkpoint "$work/acg/checkpoints/step-00000001" > /dev/null
  "$B/milv-score" run "$ds" --table imagined > /dev/null
  "$B/milv-score" curate "$ds" --top-fraction 0.8 > /dev/null
fi
echo "== milv-mcap (release)"
cargo bench -q -p milv-mcap --bench export -- "$ds" "$work/rust.mcap" "$repeats" | tee "$work/rust.jsonl"
echo "== python mcap writer"
: > "$work/python.jsonl"
for _ in $(seq "$repeats"); do
  .venv/bin/python tools/bench/export_mcap.py "$ds" "$work/python.mcap" | tee -a "$work/python.jsonl"
done
echo "== raw copy of the same bytes"
.venv/bin/python - "$work" "$repeats" <<'PY' | tee "$work/copy.jsonl"
import json, os, sys, time
w, n = sys.argv[1], int(sys.argv[2])
for _ in range(n):
    t = time.perf_counter()
    with open(f"{w}/rust.mcap", "rb") as src, open(f"{w}/copy.bin", "wb") as dst:
        while chunk := src.read(1 << 20):
            dst.write(chunk)
        dst.flush()
        os.fsync(dst.fileno())
    print(json.dumps({"bytes": os.path.getsize(f"{w}/copy.bin"), "seconds": time.perf_counter() - t}))
PY
.venv/bin/python - "$work" <<'PY'
import json, statistics, sys
w = sys.argv[1]
def load(n):
    return [json.loads(l) for l in open(f"{w}/{n}.jsonl") if l.strip()]
r, p, c = load("rust"), load("python"), load("copy")
med = lambda xs, k: statistics.median(x[k] for x in xs)
rs, ps, cs = med(r, "seconds"), med(p, "seconds"), med(c, "seconds")
mb = lambda xs, s: med(xs, "bytes") / s / 1e6
print(f"messages: milv-mcap {r[0]['messages']}, python {p[0]['messages']}")
print(f"milv-mcap {rs:.3f} s ({r[0]['messages'] / rs:,.0f} msg/s, {mb(r, rs):.0f} MB/s)")
print(f"python    {ps:.3f} s ({p[0]['messages'] / ps:,.0f} msg/s, {mb(p, ps):.0f} MB/s)")
print(f"raw copy  {cs:.3f} s ({mb(c, cs):.0f} MB/s)")
print(f"milv-mcap / python throughput: {ps / rs:.1f}x; milv-mcap at {mb(r, rs) / mb(c, cs) * 100:.0f} % of the copy")
PY
