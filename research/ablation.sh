#!/usr/bin/env bash
# The paper's Table 4 rows on a CPU (docs/experiments/table4-ablation.md): none (the UNDC baseline:
# one scale, plain convolutions), +GDFEM (one scale), +DFFM (no CRPM) start from the shipped AGNDC
# with every tensor they share with it (--init-matching), the full model from all of it as the
# control. All four put the surface nets prior on the shipped weights, so their finest vertex heads
# restart at zero and every variant starts exactly at surface nets (a knocked-out module would
# otherwise leave the old head adding offsets that no longer fit: vertex loss ~1000x the trained
# one). Then the same recipe and steps: C steps of scale 1 where the variant has one (without CRPM
# scale 1 lost its CRPM too), then S of the finest scale. Each is scored on the dev meshes at 64^3
# as remeshed (normal filter on) and as contoured (`--no-normal-filter`, the network's own vertices;
# runs "<variant>_unfiltered"); the table is research/learning_curve_table.py RUNS
# (rows "<variant> @ S").
# What this measures: how fast each variant's trained features relearn the vertices, at equal
# steps; not what retraining each variant from scratch would reach (a GPU's work).
# Resumable: a finished run or evaluation is skipped, a stopped run continues.
#   bash research/ablation.sh DATA [RUNS]      e.g. DATA=runs/data (agndc train-data -n 900)
# Optional: AGNDC_ABLATION_STEPS=S,C (default 250,100); AGNDC_CURVE_MINUTES caps each train call.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${1:?usage: ablation.sh DATA [RUNS]}
runs=${2:-runs/ablation}
dev=${AGNDC_DEV:-../shared/data/dev}
IFS=, read -r finest coarse <<< "${AGNDC_ABLATION_STEPS:-250,100}"
init=agndc_core/weights/agndc.safetensors
common=(--data "$data" --init "$init" --init-matching --batch 4 --lr 5e-4 --seed 21
        --quadric-floor 1.0 --ema 0.98 --outside-crops --threads 2 --val-steps "$finest")
if [[ -n "${AGNDC_CURVE_MINUTES:-}" ]]; then common+=(--max-minutes "$AGNDC_CURVE_MINUTES"); fi
source research/study_runs.sh
# the shipped model's architecture, with the surface nets prior (default)
shipped='"width": 16, "snake_kernel": 5, "band_radius": 4'

train full --model "{$shipped}" --steps "$finest,$coarse,0" || exit 0
both_scores full agndc
train none --model "{$shipped, \"levels\": 0, \"use_attention\": false, \"use_snake\": false, \"use_dffm\": false, \"use_crpm\": false}" --steps "$finest" || exit 0
both_scores none agndc
train plus_gdfem --model "{$shipped, \"levels\": 0}" --steps "$finest" || exit 0
both_scores plus_gdfem agndc
train plus_dffm --model "{$shipped, \"use_crpm\": false}" --steps "$finest,$coarse,0" || exit 0
both_scores plus_dffm agndc
.venv/bin/python research/learning_curve_table.py "$runs"
