#!/usr/bin/env bash
# The diagnostic ladder of the meta-policies (RESULTS.md, "Diagnostic ladder"): from
# behaviour cloning up to DAML human → robot, each rung one meta-training run and its
# one-shot evaluations, so the lowest failing rung is found before the next is climbed.
#
# usage: tools/ladder.sh FAMILY RUNG... [--out DIR]
#   FAMILY  drawing | pushing
#   RUNG    data  milv-sim gen + milv-ingest (EPISODES task instances, seed 11, SIZE px)
#           r0    behaviour cloning on ONE robot demo, evaluated on that instance from 5
#                 other start positions; one run per instance of R0_SEEDS (gen seeds,
#                 "11 12 13"), R0_STEPS (300) steps each; reports in r0/seed-S/
#           r1    behaviour cloning on every instance (DAML with α = 0: the demo is ignored),
#                 evaluated on the training shapes / objects at new positions
#           r2    DAML robot → robot (the inner step sees another robot demo's frames, no
#                 actions), evaluated on held-out and training tasks, own and swapped demos
#           r3    DAML human → robot, training tasks
#           r4    r3's policy on held-out tasks (reports in r3/)
#           r5    π_I on translated human demos: adds a held-out split (R5_EPISODES test
#                 instances, seed 22) and the alignments to the dataset, trains the coupled
#                 A-CycleGAN (ACG_STEPS, 2000; π_I with 8 transitions a step, lr 1e-3 and a
#                 leaky activation), translates, reports π_I's imagined actions
#                 on held-out human demos against the true ones, scores and curates
#           r6    MILV on r5's imagined latents with the TRUE robot actions
#                 (`meta --true-actions`), held-out tasks, own and swapped demos
#           r7    full MILV on r5's imagined latents and actions, held-out tasks
# Settings from the environment: EPISODES (150), SIZE (64), STEPS (1500), TRIALS per task
# and seed (3), SEEDS (0,1), THREADS (2), ACG_STEPS (2000), R5_EPISODES (24), MILV_BIN (target/debug), META_ARGS (extra
# `milv-train meta` flags for every rung, e.g. "--state" or "--lr 3e-4": one change per
# --out folder, so each experiment keeps its own reports). A rung whose run folder
# holds checkpoints resumes it (up to STEPS); every report lands in OUT/FAMILY/RUNG/.
set -euo pipefail
cd "$(dirname "$0")/.."
fam=${1:-}
shift || true
rungs=()
out=out/ladder
while [ $# -gt 0 ]; do
  case $1 in
    --out) out=$2; shift 2 ;;
    data|r0|r1|r2|r3|r4|r5|r6|r7) rungs+=("$1"); shift ;;
    *) echo "unknown argument $1 (rungs: data r0 r1 r2 r3 r4 r5 r6 r7)" >&2; exit 2 ;;
  esac
done
case $fam in
  drawing|pushing) ;;
  *) echo "usage: tools/ladder.sh drawing|pushing RUNG... [--out DIR]" >&2; exit 2 ;;
esac
[ ${#rungs[@]} -gt 0 ] || { echo "name at least one rung: data r0 r1 r2 r3 r4 r5 r6 r7" >&2; exit 2; }
: "${R0_SEEDS:=11 12 13}" "${R0_STEPS:=300}"
: "${ACG_STEPS:=2000}" "${R5_EPISODES:=24}"
: "${EPISODES:=150}" "${SIZE:=64}" "${STEPS:=1500}" "${TRIALS:=3}" "${SEEDS:=0,1}" "${THREADS:=2}"
B=${MILV_BIN:-$PWD/target/debug}
[ -x "$B/milv-train" ] || tools/setup.sh
F="$out/$fam"
ds="$F/dataset"
rt=(--threads "$THREADS")
field() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }

# meta RUNG ARGS...: meta-trains (or resumes) the rung's policy (VARIANT, daml) to STEPS
# steps on DS (default: version 1 of the ladder's dataset, the robot and human demos, so
# r5's later versions change nothing for r1-r4); RUNG is a folder under OUT/FAMILY.
meta() {
  local r=$1
  shift
  local resume=()
  ls "$F/$r/run/checkpoints"/step-* >/dev/null 2>&1 && resume=(--resume)
  "$B/milv-train" meta "${DS:-$ds@1}" --variant "${VARIANT:-daml}" --out "$F/$r/run" --steps "$STEPS" \
    --checkpoint-every 250 "${resume[@]}" "$@" ${META_ARGS:-} "${rt[@]}" --json > "$F/$r/meta.json"
  field "'meta: step %d, outer loss %.4f -> %.4f after adaptation, %.4f before (first and last tenth of the steps run)' % (d['step'], d['outer_first'], d['outer_last'], d['outer_pre_last'])" < "$F/$r/meta.json"
}

# eval RUNG NAME ARGS...: one-shot evaluation, report in RUNG/eval-NAME.json.
evaluate() {
  local r=$1 name=$2
  shift 2
  "$B/milv-train" eval "$F/$r/run" --family "$fam" --trials "$TRIALS" --seeds "$SEEDS" "$@" \
    "${rt[@]}" --json -o "$F/$r/eval-$name.json" > /dev/null
  field "'eval $name: %d/%d (%.1f %%, 95 %% CI %.1f-%.1f), wrong object %d, control %d, loss %.4f before adapting, %.4f after' % (d['successes'], d['trials'], 100*d['rate'], 100*d['wilson95'][0], 100*d['wilson95'][1], d['wrong_object'], d['control'], d.get('loss_pre', float('nan')), d.get('loss_post', float('nan')))" \
    < "$F/$r/eval-$name.json"
  field "'  objects: target moved %d, distractor %d, neither %d; target to square %.1f -> %.1f cm' % (d['pushing']['target_moved'], d['pushing']['distractor_moved'], d['pushing']['untouched'], d['pushing']['mean_gap_start_cm'], d['pushing']['mean_gap_end_cm']) if d.get('pushing') else ''" \
    < "$F/$r/eval-$name.json" | grep . || true
}

# gen_ingest N SEED DIR: milv-sim gen + milv-ingest into DIR/sim and DIR/dataset.
gen_ingest() {
  if [ -d "$3/dataset" ]; then
    echo "dataset $3/dataset exists"
  else
    "$B/milv-sim" gen --task "$fam" --episodes "$1" --seed "$2" --size "$SIZE" --out "$3/sim"
    "$B/milv-ingest" "$3/dataset" --manifest "$3/sim/manifest.jsonl" --require-actions
  fi
}

gt="$F/ground_truth.jsonl"
# The translator r5 trained, and the dataset version it curated.
translator() {
  [ -f "$F/r5/checkpoint.txt" ] || { echo "run r5 first: $1 trains on its translation" >&2; exit 2; }
  cat "$F/r5/checkpoint.txt"
}

for r in "${rungs[@]}"; do
  start=$(date +%s)
  echo "== $fam $r"
  mkdir -p "$F/$r"
  case $r in
    data)
      gen_ingest "$EPISODES" 11 "$F" ;;
    r0)
      # One instance per run: milv-sim's first instance of each gen seed.
      for s in $R0_SEEDS; do
        d="r0/seed-$s"
        mkdir -p "$F/$d"
        gen_ingest 1 "$s" "$F/$d" > /dev/null
        DS="$F/$d/dataset" STEPS=$R0_STEPS meta "$d" --alpha 0
        TRIALS=5 SEEDS=0 evaluate "$d" instance --instances "$F/$d/sim/instances.jsonl"
      done ;;
    r1)
      meta r1 --alpha 0
      evaluate r1 train --split train ;;
    r2)
      meta r2 --inner robot
      evaluate r2 test --split test
      evaluate r2 test-swap --split test --demo swap
      evaluate r2 train --split train
      evaluate r2 train-swap --split train --demo swap ;;
    r3)
      # R3 and R4 are one run (DAML human → robot), evaluated on both splits.
      meta r3
      evaluate r3 train --split train ;;
    r4)
      [ -d "$F/r3/run" ] || { echo "run r3 first: R4 evaluates its policy on held-out tasks" >&2; exit 2; }
      evaluate r3 test --split test ;;
    r5)
      if [ ! -d "$F/r5/test/sim" ]; then
        "$B/milv-sim" gen --task "$fam" --episodes "$R5_EPISODES" --seed 22 --split test --size "$SIZE" \
          --out "$F/r5/test/sim"
        "$B/milv-ingest" "$ds" --manifest "$F/r5/test/sim/manifest.jsonl" --require-actions
        "$B/milv-align" "$ds" --features motion --temperature 0 --max-band 0.2 --json > "$F/r5/align.json"
      fi
      # Both splits' human/robot demo pairs, paths relative to the file.
      (sed 's#"human":"#"human":"sim/#; s#"robot":"#"robot":"sim/#' "$F/sim/ground_truth.jsonl"
       sed 's#"human":"#"human":"r5/test/sim/#; s#"robot":"#"robot":"r5/test/sim/#' \
         "$F/r5/test/sim/ground_truth.jsonl") > "$gt"
      resume=()
      ls "$F/r5/acg/checkpoints"/step-* >/dev/null 2>&1 && resume=(--resume)
      "$B/milv-train" cyclegan "$ds" --out "$F/r5/acg" --size "$SIZE" --steps "$ACG_STEPS" "${resume[@]}" \
        --idm-batch 8 --lr-idm 0.001 --idm-slope 0.2 --alignment motion --checkpoint-every 500 --eval-every 500 \
        --grid-every "$ACG_STEPS" --truth "$gt" --eval-pairs 12 ${ACG_ARGS:-} "${rt[@]}" --json > "$F/r5/acg.json"
      ckpt=$(ls -d "$F/r5/acg/checkpoints"/step-* | sort -t- -k2 -n | tail -1)
      "$B/milv-train" translate "$ds" --checkpoint "$ckpt" "${rt[@]}" --json > "$F/r5/translate.json"
      "$B/milv-train" eval-translation "$ds" --checkpoint "$ckpt" --truth "$gt" --pairs "$R5_EPISODES" \
        "${rt[@]}" --json > "$F/r5/eval-translation.json"
      field "'translation (held-out human demos): SSIM %.3f (untranslated %.3f)' % (d['ssim'], d['ssim_untranslated'])" < "$F/r5/eval-translation.json"
      for k in translated_fit robot_demo_fit; do
        field "'$k: MAE %.3f (zero predictor %.3f, ratio %.2f), correlation %s, spread %s vs true %s' % (d['$k']['mae'], d['$k']['mae_zero'], d['$k']['mae']/d['$k']['mae_zero'], [round(c,2) for c in d['$k']['corr']], [round(x,2) for x in d['$k']['std']], [round(x,2) for x in d['$k']['std_true']])" \
          < "$F/r5/eval-translation.json"
      done
      model=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['model_id'])" "$ckpt/checkpoint.json")
      "$B/milv-score" run "$ds" --table imagined --model-id "$model" --json > "$F/r5/score.json"
      "$B/milv-score" curate "$ds" --top-fraction 0.8 --json > "$F/r5/curate.json"
      field "d['version']" < "$F/r5/curate.json" > "$F/r5/curated_version.txt"
      echo "$ckpt" > "$F/r5/checkpoint.txt" ;;
    r6)
      tr=$(translator r6)
      DS="$ds@$(cat "$F/r5/curated_version.txt")" VARIANT=milv meta r6 --translator "$tr" --truth "$gt" --true-actions
      evaluate r6 test --split test
      evaluate r6 test-swap --split test --demo swap ;;
    r7)
      tr=$(translator r7)
      DS="$ds@$(cat "$F/r5/curated_version.txt")" VARIANT=milv meta r7 --translator "$tr" --truth "$gt" \
        --allow-weak-translator
      evaluate r7 test --split test
      evaluate r7 test-swap --split test --demo swap ;;
  esac
  echo "($r took $(( ($(date +%s) - start) / 60 )) min)"
done
