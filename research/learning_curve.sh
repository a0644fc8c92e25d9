#!/usr/bin/env bash
# The learning-curve study (docs/experiments/learning-curve.md): UNDC and AGNDC at widths 16 and
# 32, trained from scratch on the same data with the same recipe, a checkpoint at finest-scale
# steps 10, 30, 100, 300 (and 1000 for UNDC), each scored on the dev meshes at 64^3; then UNDC 16
# for 3,000 steps (what a 3x longer run buys), AGNDC at width 32, and AGNDC 16 for 1,000 steps (it
# stays at surface nets), then UNDC and AGNDC 16 with --binary-targets for 3,000 steps and
# continued for 2,400 more with and without it (docs/experiments/binary-targets-curriculum.md).
# Every point is scored as remeshed and as contoured (runs "<name>_unfiltered"; the points
# quoted in docs/experiments/learning-curve.md are the contoured ones).
# Resumable: a finished run or evaluation is skipped, a stopped run continues (--resume).
#   bash research/learning_curve.sh DATA [RUNS]      e.g. DATA=runs/data (agndc train-data -n 900)
# Optional: AGNDC_CURVE_MINUTES caps each training call (it stops cleanly; run again to go on).
set -euo pipefail
cd "$(dirname "$0")/.."
data=${1:?usage: learning_curve.sh DATA [RUNS]}
runs=${2:-runs/curve}
dev=${AGNDC_DEV:-../shared/data/dev}
common=(--data "$data" --batch 4 --lr 1e-3 --seed 5 --quadric-floor 1.0 --outside-crops --threads 2)
if [[ -n "${AGNDC_CURVE_MINUTES:-}" ]]; then common+=(--max-minutes "$AGNDC_CURVE_MINUTES"); fi

source research/study_runs.sh

undc_steps=(--steps 1000 --val-steps 10,30,100,300,1000)
agndc_steps=(--steps 300,100,100 --val-steps 10,30,100,300)
agndc_model='"snake_kernel": 5, "band_radius": 4'

train undc16 --undc --model '{"width": 16}' "${undc_steps[@]}" || exit 0
both_scores undc16 undc
train agndc16 --model "{\"width\": 16, $agndc_model}" "${agndc_steps[@]}" || exit 0
both_scores agndc16 agndc
train undc32 --undc --model '{"width": 32}' "${undc_steps[@]}" || exit 0
both_scores undc32 undc
train undc16_long --undc --model '{"width": 16}' --steps 3000 --val-steps 1000,2000,3000 || exit 0
both_scores undc16_long undc
train agndc32 --model "{\"width\": 32, $agndc_model}" "${agndc_steps[@]}" || exit 0
both_scores agndc32 agndc
train agndc16_long --model "{\"width\": 16, $agndc_model}" --steps 1000,100,100 --val-steps 300,1000 || exit 0
both_scores agndc16_long agndc
# the pair with --binary-targets (AGNDC with only the last vertex layer started at zero), same
# data, seed and 3,000-step schedule
train bt_undc16_long --undc --model '{"width": 16}' --steps 3000 --val-steps 1000,2000,3000 \
    --binary-targets || exit 0
both_scores bt_undc16_long undc
train bt_agndc16_long --model "{\"width\": 16, $agndc_model}" --steps 3000,100,100 \
    --val-steps 500,1000,2000,3000 --binary-targets || exit 0
both_scores bt_agndc16_long agndc
# both continued for 2,400 more steps: a warm restart of the cosine schedule at
# half the rate, new crops (seed 6), the coarse scales kept as they are; first with the option,
# then with the true targets (the curriculum that works: the noise-free targets teach the
# start, the true depths what the faces' neighbours pin)
continued=(--val-steps 1200,2400 --lr 5e-4 --seed 6)
agndc_from=(--init "$runs/bt_agndc16_long/step-003000.safetensors")
undc_from=(--init "$runs/bt_undc16_long/step-003000.safetensors")
train bt_agndc16_cont --model "{\"width\": 16, $agndc_model}" --steps 2400,0,0 "${continued[@]}" \
    "${agndc_from[@]}" --binary-targets || exit 0
both_scores bt_agndc16_cont agndc
train bt_undc16_cont --undc --model '{"width": 16}' --steps 2400 "${continued[@]}" \
    "${undc_from[@]}" --binary-targets || exit 0
both_scores bt_undc16_cont undc
train dt_agndc16_cont --model "{\"width\": 16, $agndc_model}" --steps 2400,0,0 "${continued[@]}" \
    "${agndc_from[@]}" || exit 0
both_scores dt_agndc16_cont agndc
train dt_undc16_cont --undc --model '{"width": 16}' --steps 2400 "${continued[@]}" \
    "${undc_from[@]}" || exit 0
both_scores dt_undc16_cont undc
.venv/bin/python research/learning_curve_table.py "$runs"
