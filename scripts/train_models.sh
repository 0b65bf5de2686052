#!/usr/bin/env bash
# Reproduces the shipped models and models/MODEL_CARD.md from scratch (`make models`):
#   1. simulation only: GAT with geometry features and the uncertainty head, trained over the
#      whole apartment floor (the room the cameras see), and the site-independent model
#      (rays + geometry, random rooms only, never this layout), in parallel;
#   2. blocked 5-fold cross-validation of sim + real fine-tuning on dev.json, twice: by time
#      segments and by floor regions (the proxy for a recording that walks elsewhere);
#   3. the shipped model: the simulation model fine-tuned on sim + all of dev.json;
#   4. the hybrid calibration (network sigma scale, analytic sigma per camera count) from the
#      spatial cross-validation, written into the shipped models;
#   5. evaluation on dev.json (per frame and temporal, through the host's aggregator), the
#      coverage maps, the demo on simulation, the inference benchmark, and the card.
# About 75 minutes on 2 cores. Outputs in build/models; the shipped files are copied to models/.
set -euo pipefail
cd "$(dirname "$0")/.."
DEV=${DEV:-../shared/datasets/wheresthefellow/dev.json}
SITE=deploy/sites/wtf-apartment.toml
OUT=${OUT:-build/models}
SB=".venv/bin/superbody"
mkdir -p "$OUT"
test -f "$DEV" || { echo "dev.json not found at $DEV (set DEV=...)" >&2; exit 2; }

COMMON=(--site "$SITE" --arch gat --geometry --no-progress)
# Fine-tuning on real data: each sample 20 times per epoch, and each proper subset of its views
# (a 3-camera frame as three single-view and three two-view frames, same truth) 10 times.
FINETUNE=(--real "$DEV" --real-repeat 20 --real-subset-repeat 10 --sim-samples 10000 --sim-seed 1 --epochs 8 --lr 5e-4 --patience 3)

# A step is skipped when its output exists (delete build/models to start over).
train() {  # NAME ARGS...
  local name=$1; shift
  if [ -f "$OUT/$name.pt" ]; then echo "reusing $OUT/$name.* (delete it to retrain)"; return; fi
  $SB train "$@" --out "$OUT" --name "$name" > "$OUT/$name.log" 2>&1 || { tail -n 20 "$OUT/$name.log" >&2; return 1; }
  tail -n 6 "$OUT/$name.log"
}
crossval() {  # SPLIT
  local split=$1
  if [ -f "$OUT/crossval-$split.npz" ]; then echo "reusing $OUT/crossval-$split.*"; return; fi
  $SB crossval "${COMMON[@]}" "${FINETUNE[@]}" --init "$OUT/wtf-sim.pt" --folds 5 --split "$split" --threads 1 \
      --json-out "$OUT/crossval-$split.json" --predictions-out "$OUT/crossval-$split.npz" 2> "$OUT/crossval-$split.log" | tee "$OUT/crossval-$split.txt"
}

# 1. Simulation only, one thread each.
train wtf-sim "${COMMON[@]}" --sim-samples 30000 --epochs 30 --threads 1 --max-minutes 40 &
train site-independent --site "$SITE" --arch gat --variant rays --geometry --max-views 4 --random-sites 60 \
    --sim-samples 30000 --epochs 30 --threads 1 --max-minutes 40 --no-progress &
wait

$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/wtf-sim.fp32.onnx" --model "$OUT/wtf-sim.int8.onnx" \
    --json-out "$OUT/eval-sim.json" | tee "$OUT/eval-sim.txt"
$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/site-independent.fp32.onnx" --model "$OUT/site-independent.int8.onnx" \
    --temporal --json-out "$OUT/eval-site-independent.json" | tee "$OUT/eval-site-independent.txt"

# 2 and 3: the two cross-validations and the shipped fine-tuning, in parallel.
crossval time &
crossval space &
train wtf-apartment "${COMMON[@]}" "${FINETUNE[@]}" --init "$OUT/wtf-sim.pt" --threads 1 &
wait

# 4. The hybrid calibration from the spatial cross-validation, into the shipped pair.
$SB calibrate hybrid --cv "$OUT/crossval-space.npz" --dataset "$DEV" --site "$SITE" \
    --model "$OUT/wtf-apartment.fp32.onnx" --model "$OUT/wtf-apartment.int8.onnx" --json-out "$OUT/hybrid-space.json" | tee "$OUT/hybrid-space.txt"
$SB calibrate hybrid --cv "$OUT/crossval-time.npz" --dataset "$DEV" --site "$SITE" --json-out "$OUT/hybrid-time.json" | tee "$OUT/hybrid-time.txt"
cp "$OUT/wtf-apartment.fp32.onnx" "$OUT/wtf-apartment.int8.onnx" "$OUT/site-independent.fp32.onnx" "$OUT/site-independent.int8.onnx" models/

# 5. The shipped model on dev.json (its own fine-tuning data: optimistic), per frame and temporal.
$SB eval --dataset "$DEV" --site "$SITE" --model models/wtf-apartment.fp32.onnx --model models/wtf-apartment.int8.onnx \
    --temporal --json-out "$OUT/eval-shipped.json" --plots "$OUT/plots-shipped" | tee "$OUT/eval-shipped.txt"
$SB eval --dataset "$DEV" --site "$SITE" --estimator analytic --temporal --json-out "$OUT/eval-analytic.json" | tee "$OUT/eval-analytic.txt"
$SB coverage --site "$SITE" --model models/wtf-apartment.int8.onnx --dataset "$DEV" --out models/card --json-out "$OUT/coverage.json"
$SB demo --duration 60 --clock-scale 3 --port 17480 --no-table --json-summary "$OUT/demo.json"
.venv/bin/python benchmarks/model_bench.py --model models/wtf-apartment.int8.onnx --json-out "$OUT/bench-model.json" | tee "$OUT/bench-model.txt"
.venv/bin/python scripts/model_card.py --out-dir "$OUT" --card models/MODEL_CARD.md
echo "models and card written; see models/MODEL_CARD.md"
