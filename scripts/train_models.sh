#!/usr/bin/env bash
# Reproduces the shipped models and models/MODEL_CARD.md from scratch (`make models`):
#   1. simulation only (DS2-like): GAT with geometry features, trained on the apartment site;
#   2. blocked 5-fold cross-validation of sim + real fine-tuning on dev.json (DS1-like);
#   3. the shipped model: the simulation model fine-tuned on sim + all of dev.json;
#   4. the 3D-feature (depth) variant, simulation only;
#   5. the site-independent model: rays + geometry, random rooms only (never this layout);
#   6. evaluation of each on dev.json, the demo on simulation, the inference benchmark, the card.
# About 40 minutes on 2 cores. Outputs in build/models; the shipped files are copied to models/.
set -euo pipefail
cd "$(dirname "$0")/.."
DEV=${DEV:-../shared/datasets/wheresthefellow/dev.json}
SITE=deploy/sites/wtf-apartment.toml
OUT=${OUT:-build/models}
SB=".venv/bin/superbody"
mkdir -p "$OUT"
test -f "$DEV" || { echo "dev.json not found at $DEV (set DEV=...)" >&2; exit 2; }

COMMON=(--site "$SITE" --arch gat --geometry --no-progress)
FINETUNE=(--real "$DEV" --real-repeat 20 --sim-samples 10000 --sim-seed 1 --epochs 8 --lr 5e-4 --patience 3)

# A training step is skipped when its checkpoint exists (delete build/models to start over).
train() {  # NAME ARGS...
  local name=$1; shift
  if [ -f "$OUT/$name.pt" ]; then echo "reusing $OUT/$name.* (delete it to retrain)"; return; fi
  $SB train "$@" --out "$OUT" --name "$name" > "$OUT/$name.log" 2>&1 || { tail -n 20 "$OUT/$name.log" >&2; return 1; }
  tail -n 6 "$OUT/$name.log"
}

# 1, 4, 5 in parallel (one thread each): simulation only; 3D features; site-independent (random rooms only).
train wtf-sim "${COMMON[@]}" --sim-samples 30000 --epochs 30 --threads 1 &
train wtf-sim-3d "${COMMON[@]}" --3d --sim-samples 30000 --epochs 30 --threads 1 &
train site-independent --site "$SITE" --arch gat --variant rays --geometry --max-views 4 --random-sites 60 \
    --sim-samples 30000 --epochs 30 --threads 1 --no-progress &
wait

$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/wtf-sim.fp32.onnx" --model "$OUT/wtf-sim.int8.onnx" \
    --json-out "$OUT/eval-sim.json" --plots "$OUT/plots-sim" | tee "$OUT/eval-sim.txt"
$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/wtf-sim-3d.fp32.onnx" --model "$OUT/wtf-sim-3d.int8.onnx" \
    --json-out "$OUT/eval-sim-3d.json" | tee "$OUT/eval-sim-3d.txt"
$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/site-independent.fp32.onnx" --model "$OUT/site-independent.int8.onnx" \
    --json-out "$OUT/eval-site-independent.json" | tee "$OUT/eval-site-independent.txt"

# 2. Sim + real, blocked 5-fold cross-validation (each fold fine-tunes the simulation model).
$SB crossval "${COMMON[@]}" "${FINETUNE[@]}" --init "$OUT/wtf-sim.pt" --folds 5 --json-out "$OUT/crossval.json" 2> "$OUT/crossval.log" | tee "$OUT/crossval.txt"

# 3. The shipped model: the simulation model fine-tuned on sim + all of dev.json.
train wtf-apartment "${COMMON[@]}" "${FINETUNE[@]}" --init "$OUT/wtf-sim.pt"
cp "$OUT/wtf-apartment.fp32.onnx" "$OUT/wtf-apartment.int8.onnx" "$OUT/site-independent.fp32.onnx" "$OUT/site-independent.int8.onnx" models/
$SB eval --dataset "$DEV" --site "$SITE" --model models/wtf-apartment.fp32.onnx --model models/wtf-apartment.int8.onnx \
    --json-out "$OUT/eval-shipped.json" --plots "$OUT/plots-shipped" | tee "$OUT/eval-shipped.txt"

# 6. On simulation (the demo), speed, and the card.
$SB demo --duration 60 --clock-scale 3 --port 17480 --no-table --json-summary "$OUT/demo.json"
.venv/bin/python benchmarks/model_bench.py --model models/wtf-apartment.int8.onnx --json-out "$OUT/bench-model.json" | tee "$OUT/bench-model.txt"
.venv/bin/python scripts/model_card.py --out-dir "$OUT" --card models/MODEL_CARD.md
echo "models and card written; see models/MODEL_CARD.md"
