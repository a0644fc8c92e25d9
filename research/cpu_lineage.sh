#!/usr/bin/env bash
# The background CPU lineage: the best recipe (the curriculum of docs/experiments/
# binary-targets-curriculum.md) trained on one thread at the lowest priority, resumable at any
# moment. Run it again to go on where it stopped (each stage resumes bit-exactly from its state
# shards; a finished stage is skipped):
#   nohup nice -n 19 bash research/cpu_lineage.sh [DATA] [RUNS] [undc] > lineage.log 2>&1 &
# Stage 1: AGNDC w16 from scratch with --binary-targets, 3,000 finest-scale steps (+100, +100);
# stage 2: its step-3000 checkpoint continued 2,400 steps on the true targets; stage 3: the
# shipped AGNDC (better than stages 1-2 on the validation family) continued 6,000 steps on 900
# new shapes with --wrinkled 0.5 (DATA_wrinkled; docs/experiments/wrinkled-training.md); stage 4:
# stage 3's step 2,000 (its best on the validation family; later steps at 2e-4 drift) continued
# 6,000 steps on the same data at a quarter of the learning rate with a slower EMA; stage 5:
# the shipped AGNDC continued 1,500 steps on DATA plus 200 thin sheets (DATA_sheets, agndc
# train-data --sheets 1.0; docs/experiments/sheet-training.md); stage 6: its step 1,000 (its
# best on the validation family) continued 4,000 steps at half the learning rate; stage 7: stage
# 6's step 2,000 (shipped as agndc) continued 4,000 steps on DATA, the sheets and the wrinkled
# shapes together, at a lower learning rate and a slower EMA. Stages 5-7 run before stage 4,
# which waits with its state where it stopped. Pause it
# for a benchmark with kill -STOP / kill -CONT on the `agndc train` process.
# With a third argument `undc`: the lineage's UNDC twin instead (the same data, steps, seeds and
# curriculum), the baseline of the AGNDC-against-UNDC comparison in docs/training.md.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${1:-/work/data/v2_train}
runs=${2:-/work/runs}
which=${3:-agndc}
export OMP_NUM_THREADS=1
if [[ ! -f "$data/.done" ]]; then
    .venv/bin/agndc train-data -o "$data" -n 900 --workers 1 && touch "$data/.done"
fi
model='{"width": 16, "snake_kernel": 5, "band_radius": 4}'
common=(--data "$data" --batch 4 --quadric-floor 1.0 --outside-crops --threads 1 --model "$model")

stage() {  # stage NAME ARGS...: run or resume one stage; skip it once final.safetensors exists
    local name=$1; shift
    [[ -f "$runs/$name/final.safetensors" ]] && return 0
    local resume=()
    [[ -f "$runs/$name/run.json" ]] && resume=(--resume)
    .venv/bin/agndc train -o "$runs/$name" "${common[@]}" "$@" "${resume[@]}"
}

if [[ $which == undc ]]; then
    stage bt_undc16_long --undc --model '{"width": 16}' --lr 1e-3 --seed 5 --steps 3000 \
        --binary-targets --val-steps 3000
    stage dt_undc16_cont --undc --model '{"width": 16}' \
        --init "$runs/bt_undc16_long/step-003000.safetensors" --lr 5e-4 --seed 6 --steps 2400
    exit 0
fi
stage bt_agndc16_long --lr 1e-3 --seed 5 --steps 3000,100,100 --binary-targets --val-steps 3000
stage dt_agndc16_cont --init "$runs/bt_agndc16_long/step-003000.safetensors" --lr 5e-4 --seed 6 \
    --steps 2400,0,0
wrinkled="${data}_wrinkled"
if [[ ! -f "$wrinkled/.done" ]]; then
    .venv/bin/agndc train-data -o "$wrinkled" -n 900 --seed0 10000 --wrinkled 0.5 --workers 1 \
        && touch "$wrinkled/.done"
fi
stage wr_agndc16 --data "$wrinkled" --init agndc_core/weights/agndc.safetensors \
    --model '{"width": 16, "snake_kernel": 5, "band_radius": 4, "surface_nets_prior": false}' \
    --lr 2e-4 --ema 0.99 --seed 7 --steps 6000,0,0 --val-steps 1000,2000,3000,4000,5000,6000
sheets="${data}_sheets"
if [[ ! -f "$sheets/.done" ]]; then
    .venv/bin/agndc train-data -o "$sheets" -n 200 --seed0 20000 --sheets 1.0 --workers 1 \
        && touch "$sheets/.done"
fi
shipped_config='{"width": 16, "snake_kernel": 5, "band_radius": 4, "surface_nets_prior": false}'
# stage 5 started from the weights shipped before it (gpu1, sha256 in docs/experiments/
# sheet-training.md); stage 6 goes on from its step 1,000
stage sh_agndc16 --data "$data,$sheets" --init agndc_core/weights/agndc.safetensors \
    --model "$shipped_config" --lr 1e-4 --ema 0.99 --seed 9 --steps 1500,0,0 \
    --val-steps 500,1000,1500
stage sh_agndc16_cont --data "$data,$sheets" --init "$runs/sh_agndc16/step-001000.safetensors" \
    --model "$shipped_config" --lr 5e-5 --ema 0.995 --seed 10 --steps 4000,0,0 \
    --val-steps 1000,2000,3000,4000
stage mix_agndc16 --data "$data,$sheets,$wrinkled" \
    --init "$runs/sh_agndc16_cont/step-002000.safetensors" --model "$shipped_config" \
    --lr 3e-5 --ema 0.999 --seed 13 --steps 4000,0,0 --val-steps 1000,2000,3000,4000
stage wr_agndc16_low --data "$wrinkled" --init "$runs/wr_agndc16/step-002000.safetensors" \
    --model '{"width": 16, "snake_kernel": 5, "band_radius": 4, "surface_nets_prior": false}' \
    --lr 5e-5 --ema 0.999 --seed 8 --steps 6000,0,0 --val-steps 1000,2000,3000,4000,5000,6000
