#!/usr/bin/env bash
# The paper's experiment end to end, in one command: for each task family (drawing,
# pushing) milv-sim generates human demos, robot demos, robot random videos and loosely
# paired clips; milv-ingest builds a versioned dataset; milv-align aligns the pairs;
# A-CycleGAN is trained coupled (MILV) and decoupled (DeGI); each translates the human
# demos; milv-score scores and curates; the five meta-policies (DAML, DeGI, FeedImg,
# WStable, MILV) meta-train from pinned versions; each is evaluated one-shot in milv-sim
# on the held-out tasks and packed under OUT/policies/; the success tables (the paper's
# Tables 1 and 2) are written.
#
# usage: tools/reproduce.sh small|medium|full [--out DIR]
#   small   this 2-core CPU machine in under 2 hours (release binaries, after the build):
#           64×64 frames, 300 task instances per family, 1,500 A-CycleGAN and 1,500 meta
#           steps, 4 trials per held-out task × seeds 0,1 (96 drawing / 64 pushing trials)
#   medium  the same data with the ladder's training lengths (4,500 meta steps, 3,000
#           A-CycleGAN steps): about 5 hours here
#   full    the paper's scale, for a GPU: 128×128, 1,320 drawing / 1,000 pushing demos,
#           long trainings, 25 trials per task × 2 seeds (set DEVICE=cpu to force the CPU)
# π_I trains with 8 transitions per step at lr 1e-3 and a leaky activation (IDM_ARGS):
# with the paper's batch 1, lr 0.01 and ReLU it predicts a constant at 64 px (RESULTS.md,
# ladder R5). Any setting can be overridden from the environment (SIZE, EPISODES,
# ACG_STEPS, META_STEPS, TRIALS, SEEDS, THREADS, DEVICE, FAMILIES, IDM_ARGS,
# ALLOW_WEAK_TRANSLATOR, MILV_BIN).
set -euo pipefail
cd "$(dirname "$0")/.."
scale=${1:-}
shift || true
out=""
while [ $# -gt 0 ]; do
  case $1 in
    --out) out=$2; shift 2 ;;
    *) echo "unknown argument $1" >&2; exit 2 ;;
  esac
done
case $scale in
  small)
    : "${SIZE:=64}" "${EPISODES:=300}" "${ACG_STEPS:=1500}" "${META_STEPS:=1500}"
    : "${TRIALS:=4}" "${SEEDS:=0,1}" "${THREADS:=2}" "${DEVICE:=cpu}" ;;
  medium)
    : "${SIZE:=64}" "${EPISODES:=300}" "${ACG_STEPS:=3000}" "${META_STEPS:=4500}"
    : "${TRIALS:=4}" "${SEEDS:=0,1}" "${THREADS:=2}" "${DEVICE:=cpu}" ;;
  full)
    : "${SIZE:=128}" "${EPISODES:=}" "${ACG_STEPS:=50000}" "${META_STEPS:=30000}"
    : "${TRIALS:=25}" "${SEEDS:=0,1}" "${THREADS:=8}" "${DEVICE:=auto}" ;;
  *) echo "usage: tools/reproduce.sh small|medium|full [--out DIR]" >&2; exit 2 ;;
esac
: "${FAMILIES:=drawing pushing}"
out=${out:-out/reproduce-$scale}
: "${IDM_ARGS:=--idm-batch 8 --lr-idm 0.001 --idm-slope 0.2}"
tools/setup.sh
# Release binaries: the trainings run several times faster than in a debug build.
if [ -z "${MILV_BIN:-}" ]; then
  cargo build --release --locked -p milv -p milv-train --bins --quiet
fi
B=${MILV_BIN:-$PWD/target/release}
mkdir -p "$out"
log="$out/reproduce.log"
: > "$log"
say() { echo "== $*" | tee -a "$log"; }
# The value of a JSON field in a one-line JSON document on stdin.
field() { python3 -c "import json,sys; print(json.load(sys.stdin)$1)"; }
rt=(--threads "$THREADS" --device "$DEVICE")
start=$(date +%s)
reports=()
for fam in $FAMILIES; do
  n=$EPISODES
  if [ -z "$n" ]; then
    # The paper's dataset sizes (section 5.1).
    if [ "$fam" = drawing ]; then n=1320; else n=1000; fi
  fi
  F="$out/$fam"
  ds="$F/dataset"
  mkdir -p "$F"
  say "$fam: milv-sim gen ($n task instances at ${SIZE}x${SIZE})"
  "$B/milv-sim" gen --task "$fam" --episodes "$n" --seed 11 --size "$SIZE" --out "$F/sim" | tee -a "$log"
  say "$fam: milv-ingest"
  "$B/milv-ingest" "$ds" --manifest "$F/sim/manifest.jsonl" --require-actions | tee -a "$log"
  # Best-path decoding (--temperature 0) in a fixed band, as when RESULTS.md was measured.
  say "$fam: milv-align (motion features, from pixels, best path)"
  "$B/milv-align" "$ds" --features motion --temperature 0 --max-band 0.2 --truth "$F/sim/warps.jsonl" | tee -a "$log"
  for kind in coupled decoupled; do
    flag=()
    [ "$kind" = decoupled ] && flag=(--decoupled)
    say "$fam: A-CycleGAN $kind, $ACG_STEPS steps"
    "$B/milv-train" cyclegan "$ds" --out "$F/acg-$kind" --size "$SIZE" --steps "$ACG_STEPS" \
      $IDM_ARGS --alignment motion --checkpoint-every "$ACG_STEPS" \
      --grid-every "$ACG_STEPS" "${flag[@]}" "${rt[@]}" | tee -a "$log"
    ckpt=$(ls -d "$F/acg-$kind"/checkpoints/step-* | tail -1)
    echo "$ckpt" > "$F/acg-$kind/checkpoint.txt"
    say "$fam: translate ($kind), eval-translation, score, curate"
    "$B/milv-train" translate "$ds" --checkpoint "$ckpt" "${rt[@]}" | tee -a "$log"
    "$B/milv-train" eval-translation "$ds" --checkpoint "$ckpt" --truth "$F/sim/ground_truth.jsonl" \
      "${rt[@]}" | tee -a "$log"
    model=$(field "['model_id']" < "$ckpt/checkpoint.json")
    "$B/milv-score" run "$ds" --table imagined --model-id "$model" | tee -a "$log"
    cur=$("$B/milv-score" curate "$ds" --top-fraction 0.8 --json)
    echo "$cur" >> "$log"
    echo "$cur" | field "['version']" > "$F/acg-$kind/curated_version.txt"
  done
  vc=$(cat "$F/acg-coupled/curated_version.txt")
  vd=$(cat "$F/acg-decoupled/curated_version.txt")
  for variant in daml milv wstable feedimg degi; do
    case $variant in
      daml) v=$vc; tr=() ;;
      degi) v=$vd; tr=(--translator "$(cat "$F/acg-decoupled/checkpoint.txt")") ;;
      *) v=$vc; tr=(--translator "$(cat "$F/acg-coupled/checkpoint.txt")") ;;
    esac
    # The imagined-data variants check the translator against the simulator's ground
    # truth first: a translator whose imagined actions do not follow the true ones is
    # refused (ALLOW_WEAK_TRANSLATOR=1 trains on them anyway) and its row left out.
    check=()
    [ "$variant" != daml ] && check=(--truth "$F/sim/ground_truth.jsonl")
    [ "$variant" != daml ] && [ "${ALLOW_WEAK_TRANSLATOR:-0}" = 1 ] && check+=(--allow-weak-translator)
    say "$fam: meta-train $variant on $ds@$v, $META_STEPS steps"
    if ! "$B/milv-train" meta "$ds@$v" --variant "$variant" "${tr[@]}" --out "$F/meta-$variant" \
      --steps "$META_STEPS" --checkpoint-every "$META_STEPS" "${check[@]}" "${rt[@]}" \
      2> "$F/meta-$variant.stderr" | tee -a "$log"; then
      cat "$F/meta-$variant.stderr" | tee -a "$log" >&2
      grep -q "refusing to train" "$F/meta-$variant.stderr" || exit 1
      say "$fam: $variant refused: the translator's imagined actions do not follow the true ones"
      continue
    fi
    cat "$F/meta-$variant.stderr" >> "$log"
    say "$fam: one-shot eval of $variant ($TRIALS trials per held-out task, seeds $SEEDS)"
    "$B/milv-train" eval "$F/meta-$variant" --family "$fam" --trials "$TRIALS" --seeds "$SEEDS" \
      -o "$F/eval-$variant.json" "${rt[@]}" | tee -a "$log"
    reports+=("$F/eval-$variant.json")
    # The policy and its translator's G and F (f16, one copy per A-CycleGAN), ready to
    # re-check with `milv-train eval` (samples/policies/ holds small's).
    "$B/milv-train" pack "$F/meta-$variant" --out "$out/policies/$fam-$variant" --half \
      --translators "$out/policies/translators" | tee -a "$log"
  done
done
say "success tables"
"$B/milv-train" table "${reports[@]}" -o "$out/tables.md" | tee -a "$log"
mins=$(( ($(date +%s) - start) / 60 ))
echo "reproduce $scale finished in $mins min (after setup); tables: $out/tables.md, log: $log" | tee -a "$log"
