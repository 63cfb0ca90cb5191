#!/usr/bin/env bash
# The whole pipeline on the bundled samples: ingest human and robot clips with their
# action sidecars, align the paired clips, train a (short) A-CycleGAN and translate the
# human clips into imagined robot data, score every frame's quality and curate by it,
# meta-train a (short) MILV policy and evaluate it one-shot in milv-sim, export MCAP and
# Rerun recordings, then inspect and verify the dataset. Prints where everything is.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup.sh

BIN=${MILV_BIN:-target/debug}
OUT=${MILV_DEMO_OUT:-out/demo}
DS="$OUT/dataset"
rm -rf "$OUT"
mkdir -p "$OUT"

echo "== milv-ingest: bundled samples (samples/manifest.jsonl)"
"$BIN/milv-ingest" "$DS" --manifest samples/manifest.jsonl
echo "== milv-ingest: simulated tabletop episodes (samples/sim, made by milv-sim gen)"
"$BIN/milv-ingest" "$DS" --manifest samples/sim/drawing/manifest.jsonl --manifest samples/sim/pushing/manifest.jsonl --require-actions
echo "== milv-ingest again: a no-op (episode ids are content hashes)"
"$BIN/milv-ingest" "$DS" --manifest samples/manifest.jsonl
echo "== milv-align: frame correspondences of the loosely paired human/robot clips"
echo "   (simulated pairs on their end-effector states, scored against the true time warps)"
cat samples/sim/drawing/warps.jsonl samples/sim/pushing/warps.jsonl > "$OUT/warps.jsonl"
SIM_PAIRS=$(sed 's/.*"pair_id":"\([^"]*\)".*/\1/' "$OUT/warps.jsonl" | paste -sd,)
"$BIN/milv-align" "$DS" --features state --pairs "$SIM_PAIRS" --truth "$OUT/warps.jsonl"
echo "   (every pair, from pixels alone: motion features)"
"$BIN/milv-align" "$DS" --features motion --truth "$OUT/warps.jsonl"
PAIR=$(head -1 samples/sim/drawing/warps.jsonl | sed 's/.*"pair_id":"\([^"]*\)".*/\1/')
"$BIN/milv-align" show "$DS" "$PAIR" --features state -o "$OUT/align_$PAIR.png"
echo "== milv-train cyclegan: A-CycleGAN + inverse dynamics, 300 steps at 64x64 (a demo, not a model)"
"$BIN/milv-train" cyclegan "$DS" --out "$OUT/acyclegan" --size 64 --steps 300 --alignment motion \
  --grid-every 100 --checkpoint-every 300
CKPT="$OUT/acyclegan/checkpoints/step-00000300"
echo "== milv-train translate: every human episode -> the imagined table (G(x), F-encoder latent, action)"
"$BIN/milv-train" translate "$DS" --checkpoint "$CKPT"
cat samples/sim/drawing/ground_truth.jsonl samples/sim/pushing/ground_truth.jsonl > "$OUT/ground_truth.jsonl"
echo "== milv-train eval-translation: translations against the simulator's ground-truth robot renderings"
"$BIN/milv-train" eval-translation "$DS" --checkpoint "$CKPT" --truth "$OUT/ground_truth.jsonl"
echo "== milv-align --features translated: the pairs again, in the robot domain"
"$BIN/milv-align" "$DS" --features translated --pairs "$SIM_PAIRS" --truth "$OUT/warps.jsonl"
echo "== milv-score run: beta_qua = Brenner x SSIM of every frame -> the scores table"
"$BIN/milv-score" run "$DS"
echo "   (and of every imagined frame)"
"$BIN/milv-score" run "$DS" --table imagined
echo "== milv-score curate: the best 80 % of frames by weight -> the curated view"
"$BIN/milv-score" curate "$DS" --top-fraction 0.8
echo "== milv-score report"
"$BIN/milv-score" report "$DS" --worst 5 --out "$OUT/quality"
echo "== milv-train meta: a MILV meta-policy on the imagined latents, frames weighted by the curated beta"
echo "   (second order, learned adaptation loss; 20 steps: a demo, not a policy)"
"$BIN/milv-train" meta "$DS" --variant milv --translator "$CKPT" --out "$OUT/meta-milv" --steps 20 \
  --checkpoint-every 20
echo "== milv-train eval: one-shot in milv-sim, one human video per trial of each held-out shape"
"$BIN/milv-train" eval "$OUT/meta-milv" --family drawing --trials 1 -o "$OUT/eval-milv.json"
"$BIN/milv-train" table "$OUT/eval-milv.json" -o "$OUT/tables.md"
echo "== milv-export mcap: human | imagined | aligned robot frames, latents, actions, beta -> MCAP (Foxglove)"
"$BIN/milv-export" mcap "$DS" --alignment motion -o "$OUT/translations.mcap"
echo "== milv-export rerun: the same as a Rerun recording, worst beta first"
"$BIN/milv-export" rerun "$DS" --alignment motion --sort beta -o "$OUT/translations.rrd"
.venv/bin/rerun rrd verify "$OUT/translations.rrd"
echo "== milv-export lerobot: the imagined frames and their actions as a LeRobot v3.0 dataset (AV1, stats.json)"
"$BIN/milv-export" lerobot "$DS" --table imagined -o "$OUT/lerobot-imagined"
echo "== milv-ingest --from-lerobot: and back into a new MILV dataset"
"$BIN/milv-ingest" "$OUT/from-lerobot" --from-lerobot "$OUT/lerobot-imagined"
if [ -x .venv-lerobot/bin/python ]; then
  echo "== LeRobot 0.6.1 itself loads the export (offline)"
  HF_HUB_OFFLINE=1 HF_LEROBOT_HOME="$OUT/.hf-lerobot" HF_HOME="$OUT/.hf" .venv-lerobot/bin/python - "$OUT/lerobot-imagined" <<'PY'
from lerobot.datasets.lerobot_dataset import LeRobotDataset
import sys
ds = LeRobotDataset("local/imagined", root=sys.argv[1], video_backend="pyav")
item = ds[0]
print(f"LeRobotDataset: {ds.num_episodes} episodes, {len(ds)} frames at {ds.fps} fps; "
      f"item 0: image {tuple(item['observation.image'].shape)}, action {item['action'].tolist()}, task {item['task']!r}")
PY
fi
echo "== milv-ds info"
"$BIN/milv-ds" info "$DS"
echo "== milv-ds log"
"$BIN/milv-ds" log "$DS"
echo "== milv-ds verify"
"$BIN/milv-ds" verify "$DS"
echo "== the same tables read by polars (no MILV code involved)"
.venv/bin/python - "$DS" <<'PY'
import os, sys
import polars as pl
eps = pl.read_delta(f"{sys.argv[1]}/episodes")
print(eps.group_by("domain", "kind").agg(pl.len().alias("episodes"), pl.col("n_frames").sum()).sort("domain", "kind"))
sys.stdout.flush()
os._exit(0)  # the deltalake reader can abort at interpreter exit (upstream issue)
PY
echo "== object storage: the samples as a dataset on S3 (a throwaway SeaweedFS on 127.0.0.1),"
echo "   ingested from S3, scored by 2 Ray partitions, verified, read back with ray.data.read_delta"
.venv/bin/python tools/s3/seaweedfs.py -- bash -c '
  set -euo pipefail
  BIN=$1 OUT=$2
  .venv/bin/python - samples <<PY
import os, pyarrow.fs as fs
s3 = fs.S3FileSystem(access_key=os.environ["AWS_ACCESS_KEY_ID"], secret_key=os.environ["AWS_SECRET_ACCESS_KEY"],
                     region="us-east-1", endpoint_override=os.environ["AWS_ENDPOINT_URL"].split("://")[1], scheme="http")
fs.copy_files("samples", "milv/inputs", destination_filesystem=s3)
PY
  MILV_INPUT_CACHE="$OUT/s3-input-cache" "$BIN/milv-ingest" s3://milv/demo --manifest s3://milv/inputs/manifest.jsonl
  .venv/bin/python tools/ray/milv_ray.py score s3://milv/demo --partitions 2 --bin "$BIN"
  "$BIN/milv-ds" verify s3://milv/demo
  "$BIN/milv-ds" log s3://milv/demo
' _ "$BIN" "$OUT"

cat <<TXT

Outputs:
  dataset           $DS   (Delta tables: episodes, frames, alignments, imagined, scores, curated; version log: $DS/_milv/versions)
  A-CycleGAN run    $OUT/acyclegan (losses.jsonl, grids/step-*.png: human | G(human) | F(G(human)), checkpoints/)
  meta-policy       $OUT/meta-milv (losses.jsonl, checkpoints/); one-shot success $OUT/eval-milv.json, $OUT/tables.md
  quality plots     $OUT/quality/beta_hist.png, $OUT/quality/beta_curves.png
  an alignment      $OUT/align_$PAIR.png (cost matrix of one human/robot pair, with its path)
  translations      $OUT/translations.mcap (open in Foxglove), $OUT/translations.rrd (.venv/bin/rerun $OUT/translations.rrd)
  LeRobot           $OUT/lerobot-imagined (LeRobotDataset("local/x", root=...)), re-imported as $OUT/from-lerobot
  read it elsewhere .venv/bin/python -c "import polars as pl; print(pl.read_delta('$DS/frames').head())"
  inspect           target/debug/milv-ds info|log|verify $DS[@VERSION]
  on S3             any DATASET may be s3://bucket/prefix (README: Object storage and Ray); the demo's S3 server is gone
  the two domains   samples/contact_sheet.png (rows: human / robot, same motion)
TXT
