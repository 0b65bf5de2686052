#!/usr/bin/env bash
# Reproduces the shipped models and models/MODEL_CARD.md from scratch (`make models`):
#   1. simulation only (DS2-like): GAT with geometry features, trained on the apartment site;
#   2. blocked 5-fold cross-validation of sim + real fine-tuning on dev.json (DS1-like);
#   3. the shipped model: the simulation model fine-tuned on sim + all of dev.json;
#   4. the 3D-feature (depth) variant, simulation only;
#   5. the site-independent model: rays + geometry, random rooms only (never this layout);
#   6. evaluation of each on dev.json, the inference benchmark, and the model card.
# About 45 minutes on 2 cores. Outputs in build/models; the shipped files are copied to models/.
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

# 1. Simulation only.
$SB train "${COMMON[@]}" --sim-samples 30000 --epochs 30 --out "$OUT" --name wtf-sim
$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/wtf-sim.fp32.onnx" --model "$OUT/wtf-sim.int8.onnx" \
    --json-out "$OUT/eval-sim.json" --plots "$OUT/plots-sim" | tee "$OUT/eval-sim.txt"

# 2. Sim + real, blocked 5-fold cross-validation (each fold fine-tunes the simulation model).
$SB crossval "${COMMON[@]}" "${FINETUNE[@]}" --init "$OUT/wtf-sim.pt" --folds 5 --json-out "$OUT/crossval.json" | tee "$OUT/crossval.txt"

# 3. The shipped model: fine-tuned on sim + all of dev.json.
$SB train "${COMMON[@]}" "${FINETUNE[@]}" --init "$OUT/wtf-sim.pt" --out "$OUT" --name wtf-apartment
cp "$OUT/wtf-apartment.fp32.onnx" "$OUT/wtf-apartment.int8.onnx" models/
$SB eval --dataset "$DEV" --site "$SITE" --model models/wtf-apartment.fp32.onnx --model models/wtf-apartment.int8.onnx \
    --json-out "$OUT/eval-shipped.json" --plots "$OUT/plots-shipped" | tee "$OUT/eval-shipped.txt"

# 4. 3D features (depth cameras), simulation only.
$SB train "${COMMON[@]}" --3d --sim-samples 30000 --epochs 30 --out "$OUT" --name wtf-sim-3d
$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/wtf-sim-3d.fp32.onnx" --model "$OUT/wtf-sim-3d.int8.onnx" \
    --json-out "$OUT/eval-sim-3d.json" | tee "$OUT/eval-sim-3d.txt"

# 5. Site-independent: world rays + geometry, trained in random rooms only.
$SB train --site "$SITE" --arch gat --variant rays --geometry --max-views 4 --random-sites 60 --sim-samples 30000 \
    --epochs 30 --no-progress --out "$OUT" --name site-independent
$SB eval --dataset "$DEV" --site "$SITE" --model "$OUT/site-independent.fp32.onnx" --model "$OUT/site-independent.int8.onnx" \
    --json-out "$OUT/eval-site-independent.json" | tee "$OUT/eval-site-independent.txt"
cp "$OUT/site-independent.fp32.onnx" "$OUT/site-independent.int8.onnx" models/

# 6. Speed, and the card.
.venv/bin/python benchmarks/model_bench.py --model models/wtf-apartment.int8.onnx --json-out "$OUT/bench-model.json" | tee "$OUT/bench-model.txt"
.venv/bin/python scripts/model_card.py --out-dir "$OUT" --card models/MODEL_CARD.md
echo "models and card written; see models/MODEL_CARD.md"
