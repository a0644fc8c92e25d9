#!/usr/bin/env bash
# The background CPU lineage: the best recipe continued on one thread at the lowest priority,
# resumable at any moment. Run it again to go on where it stopped (each stage resumes
# bit-exactly from its state shards, saved every 100 steps; a finished stage is skipped):
#   nohup nice -n 19 bash research/cpu_lineage.sh [DATA] [RUNS] [current|concluded|history|undc] \
#       > lineage.log 2>&1 &
#
# Only a stage's run folder carries its state: a new machine starts a stage again from its
# start and, the stage being seeded, draws the same crops (the weights come out close, not bit
# for bit, on another CPU). So
# `current` (the default) holds only the stages whose verdict is open, and a machine that has only
# the repository starts on them. Stages 35 and 36: the shipped AGNDC (stage 16's step 400)
# continued on its own recipe (DATA, the thin sheets and the layered parts at 5e-5, EMA 0.995)
# with two seeds, checkpoints at 400 and 800. Stages 37 and 38: stage 35's recipe with 300 parts
# of round features along the axes added (DATA_rounds, agndc train-data --rounds 1.0), seeds 29
# and 31 (docs/experiments/round-parts.md). Stage 13: agndc_fast distilled again from the AGNDC
# of stage 6 (shipped before stage 16): the teacher's vertices on DATA and the sheets (agndc
# distil-data), then the student's recipe (docs/training.md, "agndc_fast, distilled"), checkpoints
# at 1,000, 2,000 and 3,000 finest-scale steps. Stage 15: stage 13's final student continued 3,000
# steps on the same data at half the learning rate: ahead of the shipped agndc_fast on the
# validation family, behind on the centred thin sheets (docs/experiments/student.md). Stage 19:
# stage 15's final student continued 3,000 steps at half its learning rate again; its step 2,000
# is the shipped agndc_fast (agndc_student.safetensors). Stage 22: the shipped agndc_fast
# continued 2,000 steps on the teacher's targets at half stage 19's learning rate. Stage 23: stage
# 22 with 300 frames of thin struts added (DATA_struts, agndc train-data --struts 1.0, distilled
# by the teacher like the rest; docs/experiments/thin-struts.md). A stage is kept short (80-120
# min where a step takes ~6 s).
#
# concluded: the stages of the current lineage whose verdict is in, none of which beat the weights
# they started from on the validation family. Stage 8: the shipped weights continued 800 steps on
# DATA, the thin sheets, the wrinkled shapes and 900 shapes of which the grid-aligned ones are
# turned 1-15 degrees off the axes (DATA_tilted, agndc train-data --tilted 1.0), at 1e-4 and EMA
# 0.99. Stage 9: stage 8's final weights continued 800 steps at half its learning rate and EMA
# 0.995 (docs/experiments/sheet-training.md). Stage 10: the shipped weights continued on their own
# recipe with a new seed (it wanders about the shipped weights). Stage 11: the same with 900 new
# training shapes (DATA_fresh, seeds from 40,000) in place of DATA. Stage 12: the shipped weights
# on all 2,000 shapes at 3e-5, 1,200 steps. Stage 14: stage 10's recipe with 300 shapes that grow
# sharp spikes added (DATA_spikes; docs/experiments/spikes.md). Stage 20: the shipped UNDC (stage
# 18) continued 3,000 steps on the same data at half its learning rate (closer on the family,
# farther on the thin sheets: docs/training.md). Stage 21: the shipped agndc_fast continued on the
# true targets (not the teacher's) of DATA, the sheets and the layered parts at stage 19's
# learning rate, stopped after step 2,000: farther on the family and the thin sheets
# (docs/experiments/student.md). Stage 24: stage 20 with the strut frames added on their true
# targets: closer on the thin-strut validation family than stage 20 (29 of 36 shapes), level on
# the family, farther on the thin sheets. Stage 25: the shipped AGNDC continued on DATA, the
# sheets and the strut frames (stage 14's recipe): its step 400 closer on the centred frames, not
# on shifted grids; its step 800 level on the family, farther on the sheets
# (docs/experiments/thin-struts.md). Stage 26: stage 24 with the thin sheets in its data too:
# level on the family, closer on the struts, farther on the sheets than the shipped UNDC. Stage
# 28: stage 23 with the frames on their true targets: the student closer on the struts, farther on
# the thin sheets. Stage 27: stage 25 at three times its learning rate: its step 400 closer
# centred and at 128^3 and on the sheets, farther on shifted grids, softer edges. Stage 29: that
# step 400 continued at 5e-5: the centred gains given back. Stage 30: stage 27 with another seed:
# the shifted grids' loss and the softer edges repeat, the centred and sheet gains do not. Stages
# 31-33: the crease-weighted vertex loss (--crease-weight 4) on stage 27, on stage 30's seed and
# on stage 16: the shifted grids a little closer, the thin sheets farther in all three
# (docs/experiments/thin-struts.md). Stage 17: stage 16 with another seed (19): its step 400 does
# not repeat stage 16's gain on the family, and the two steps 400 averaged weight by weight score
# the mean of the two (docs/experiments/layered-parts.md). Stage 34: stage 16 with a third seed
# (23): the sheets' gain repeats, the family's does not. Their AGNDC stages start from the AGNDC
# of stage 6 (agndc_v6 below) or from a continuation of it.
#
# history: the stages behind the shipped weights and the studies beside them, rerun from their own
# starts. Stage 1: AGNDC w16 from scratch with --binary-targets, 3,000 finest-scale steps (+100,
# +100); stage 2: its step-3000 checkpoint continued 2,400 steps on the true targets
# (docs/experiments/binary-targets-curriculum.md); stage 3: the AGNDC shipped before stage 5
# continued 6,000 steps on 900 new shapes with --wrinkled 0.5 (docs/experiments/
# wrinkled-training.md); stage 4: stage 3's step 2,000 continued 6,000 steps at a quarter of the
# learning rate with a slower EMA; stage 5: the AGNDC shipped before it (gpu1, sha256 in
# docs/experiments/sheet-training.md) continued 1,500 steps on DATA plus 200 thin sheets; stage 6:
# its step 1,000 continued 4,000 steps at half the learning rate (its step 2,000 is the shipped
# agndc); stage 7: that checkpoint continued 4,000 steps on DATA, the sheets and the wrinkled
# shapes at a lower learning rate and a slower EMA (docs/experiments/sheet-training.md). Stage 18:
# the UNDC shipped before it (undc_g, sha256 46dd1859...) continued 3,000 steps on DATA and the
# wrinkled shapes (DATA_wrinkled) at 5e-4, EMA 0.995: the shipped undc
# (docs/experiments/wrinkled-surfaces.md). Stage 16: the AGNDC of stage 6 continued on DATA, the
# thin sheets and 300 layered parts (DATA_layered, agndc train-data --layered 1.0: caps, lids and
# stepped plates whose layers are about a voxel thick) at 5e-5, EMA 0.995, seed 17; its step 400
# is the shipped agndc, chosen on the validation family and confirmed on a second one
# (docs/experiments/layered-parts.md). Stages 1, 3, 5 and 18 start from weights that a checkout no
# longer has once others are shipped: they reproduce only where those weights are put back at
# agndc_core/weights/agndc.safetensors (undc.safetensors for stage 18).
#
# undc: the lineage's UNDC twin (the same data, steps, seeds and curriculum as stages 1-2), the
# baseline of the AGNDC-against-UNDC comparison in docs/training.md.
#
# Pause it for a benchmark with kill -STOP / kill -CONT on the `agndc train` process.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${1:-/work/data/v2_train}
runs=${2:-/work/runs}
which=${3:-current}
export OMP_NUM_THREADS=1
model='{"width": 16, "snake_kernel": 5, "band_radius": 4}'
shipped_config='{"width": 16, "snake_kernel": 5, "band_radius": 4, "surface_nets_prior": false}'
student_config='{"width": 16, "snake_kernel": 5, "band_radius": 4, "surface_nets_prior": false,
    "use_snake": false, "use_attention": false}'
common=(--data "$data" --batch 4 --quadric-floor 1.0 --outside-crops --threads 1 --model "$model")

generate() {  # generate FOLDER ARGS...: agndc train-data into FOLDER unless it is complete
    local folder=$1; shift
    if [[ ! -f "$folder/.done" ]]; then
        .venv/bin/agndc train-data -o "$folder" --workers 1 "$@" && touch "$folder/.done"
    fi
}

distil() {  # distil FOLDER OUT: the teacher's labels (the AGNDC of stage 6), unless complete
    if [[ ! -f "$2/.done" ]]; then
        .venv/bin/agndc distil-data --data "$1" -o "$2" --teacher "$agndc_v6" --threads 1 \
            && touch "$2/.done"
    fi
}

stage() {  # stage NAME ARGS...: run or resume one stage; skip it once final.safetensors exists
    local name=$1; shift
    [[ -f "$runs/$name/final.safetensors" ]] && return 0
    local resume=()
    [[ -f "$runs/$name/run.json" ]] && resume=(--resume)
    .venv/bin/agndc train -o "$runs/$name" "${common[@]}" "$@" "${resume[@]}"
}

continue_agndc() {  # continue_agndc WEIGHTS NAME DATA ARGS...: an AGNDC checkpoint continued
    # 800 steps on DATA (comma-separated folders), checkpoints at 400 and 800; ARGS give the rest
    local weights=$1 name=$2 folders=$3; shift 3
    stage "$name" --data "$folders" --init "$weights" --model "$shipped_config" \
        --steps 800,0,0 --val-steps 400,800 "$@"
}

# The AGNDC shipped before stage 16's step 400 (stage 6's step 2,000, sha256 fa79765a...): where
# the AGNDC stages of `concluded` and stage 16 start, and the teacher of the distilled students;
# read from the last commit that shipped it.
agndc_v6=$runs/agndc_v6.safetensors
if [[ ! -f $agndc_v6 ]]; then
    mkdir -p "$runs"
    git show f68c628:agndc_core/weights/agndc.json > "$runs/agndc_v6.json"
    git show f68c628:agndc_core/weights/agndc.safetensors > "$runs/agndc_v6.tmp"
    mv "$runs/agndc_v6.tmp" "$agndc_v6"
fi

generate "$data" -n 900
sheets="${data}_sheets"
wrinkled="${data}_wrinkled"
tilted="${data}_tilted"
layered="${data}_layered"
rounds="${data}_rounds"

case $which in
current)
    # the stages whose verdict is open, so that a machine with only the repository starts
    # on them: 35, 37 and 38 (the shipped AGNDC continued on its own recipe, then with parts of
    # round features along the axes added, with two seeds), 36 (35's second seed), then
    # 13 (whose final student stage 15 continues), 15 and 19 (which continues 15; its step 2,000
    # is the shipped agndc_fast), then 22 (the shipped agndc_fast continued) and 23 (22 with
    # thin struts added)
    generate "$sheets" -n 200 --seed0 20000 --sheets 1.0
    generate "$layered" -n 300 --seed0 60000 --layered 1.0
    # stage 35 (and 36 below): the shipped AGNDC (stage 16's step 400) continued on stage 16's
    # recipe with two seeds, checkpoints at 400 and 800
    continue_agndc agndc_core/weights/agndc.safetensors layer_agndc16_v2 \
        "$data,$sheets,$layered" --lr 5e-5 --ema 0.995 --seed 29
    # stages 37 and 38: stage 35's recipe with 300 parts of round features along the axes
    # added (train-data --rounds 1.0: pins, bosses, thin-walled tubes, shafts and holes a few
    # voxels across), seeds 29 and 31
    generate "$rounds" -n 300 --seed0 80000 --rounds 1.0
    continue_agndc agndc_core/weights/agndc.safetensors round_agndc16 \
        "$data,$sheets,$layered,$rounds" --lr 5e-5 --ema 0.995 --seed 29
    continue_agndc agndc_core/weights/agndc.safetensors round_agndc16_seed31 \
        "$data,$sheets,$layered,$rounds" --lr 5e-5 --ema 0.995 --seed 31
    continue_agndc agndc_core/weights/agndc.safetensors layer_agndc16_v2_seed31 \
        "$data,$sheets,$layered" --lr 5e-5 --ema 0.995 --seed 31
    # stage 13: agndc_fast distilled again from the AGNDC of stage 6
    distil "$data" "${data}_distilled"
    distil "$sheets" "${sheets}_distilled"
    stage student_agndc16 --data "${data}_distilled,${sheets}_distilled" \
        --init "$agndc_v6" --init-matching --model "$student_config" \
        --steps 3000,300,300 --lr 5e-4 --ema 0.99 --seed 21 --val-steps 1000,2000,3000
    # stage 15: stage 13's student continued on its own data at half its learning rate
    stage student_agndc16_cont --data "${data}_distilled,${sheets}_distilled" \
        --init "$runs/student_agndc16/final.safetensors" --model "$student_config" \
        --steps 3000,0,0 --lr 2.5e-4 --ema 0.99 --seed 22 --val-steps 1000,2000,3000
    # stage 19: stage 15's final student continued at half its learning rate again
    stage student_agndc16_cont2 --data "${data}_distilled,${sheets}_distilled" \
        --init "$runs/student_agndc16_cont/final.safetensors" --model "$student_config" \
        --steps 3000,0,0 --lr 1.25e-4 --ema 0.99 --seed 24 --val-steps 1000,2000,3000
    # stage 22: the shipped agndc_fast continued on the teacher's targets at half stage 19's
    # learning rate
    stage student_agndc16_cont3 --data "${data}_distilled,${sheets}_distilled" \
        --init agndc_core/weights/agndc_student.safetensors --model "$student_config" \
        --steps 2000,0,0 --lr 6.25e-5 --ema 0.99 --seed 27 --val-steps 1000,2000
    # stage 23: stage 22 with 300 thin-strut frames added (train-data --struts 1.0), distilled
    # by the teacher like the rest
    struts="${data}_struts"
    generate "$struts" -n 300 --seed0 70000 --struts 1.0
    distil "$struts" "${struts}_distilled"
    stage student_struts16 \
        --data "${data}_distilled,${sheets}_distilled,${struts}_distilled" \
        --init agndc_core/weights/agndc_student.safetensors --model "$student_config" \
        --steps 2000,0,0 --lr 6.25e-5 --ema 0.99 --seed 27 --val-steps 1000,2000
    ;;
concluded)
    # the stages of the current lineage whose verdict is in (none beat the shipped weights):
    # 8-12, 14, 20, 21 and 24-33, rerun from their own starts
    generate "$sheets" -n 200 --seed0 20000 --sheets 1.0
    generate "$wrinkled" -n 900 --seed0 10000 --wrinkled 0.5
    generate "$tilted" -n 900 --seed0 30000 --tilted 1.0
    continue_agndc "$agndc_v6" tilt_agndc16 "$data,$sheets,$wrinkled,$tilted" \
        --lr 1e-4 --ema 0.99 --seed 15
    stage tilt_agndc16_cont --data "$data,$sheets,$wrinkled,$tilted" \
        --init "$runs/tilt_agndc16/final.safetensors" --model "$shipped_config" \
        --lr 5e-5 --ema 0.995 --seed 16 --steps 800,0,0 --val-steps 400,800
    continue_agndc "$agndc_v6" ship_agndc16_seed17 "$data,$sheets" \
        --lr 5e-5 --ema 0.995 --seed 17
    fresh="${data}_fresh"
    generate "$fresh" -n 900 --seed0 40000
    continue_agndc "$agndc_v6" fresh_agndc16 "$fresh,$sheets" --lr 5e-5 --ema 0.995 --seed 17
    stage all_agndc16 --data "$data,$fresh,$sheets" \
        --init "$agndc_v6" --model "$shipped_config" \
        --lr 3e-5 --ema 0.995 --seed 18 --steps 1200,0,0 --val-steps 400,800,1200
    spikes="${data}_spikes"
    generate "$spikes" -n 300 --seed0 50000 --spikes 1.0
    continue_agndc "$agndc_v6" spike_agndc16 "$data,$sheets,$spikes" \
        --lr 5e-5 --ema 0.995 --seed 17
    # stage 20: the shipped UNDC (stage 18) continued on its data at half its learning rate
    stage undc_wrinkled16_cont --undc --model '{"width": 16}' --data "$data,$wrinkled" \
        --init agndc_core/weights/undc.safetensors --lr 2.5e-4 --ema 0.995 --seed 25 \
        --steps 3000 --val-steps 1000,2000,3000
    # stage 24: stage 20 with the thin-strut frames added, on their true targets
    struts="${data}_struts"
    generate "$struts" -n 300 --seed0 70000 --struts 1.0
    stage undc_struts16 --undc --model '{"width": 16}' --data "$data,$wrinkled,$struts" \
        --init agndc_core/weights/undc.safetensors --lr 2.5e-4 --ema 0.995 --seed 25 \
        --steps 3000 --val-steps 1000,2000,3000
    # stage 26: stage 24 with the thin sheets in its data too
    stage undc_struts16_sheets --undc --model '{"width": 16}' \
        --data "$data,$wrinkled,$sheets,$struts" \
        --init agndc_core/weights/undc.safetensors --lr 2.5e-4 --ema 0.995 --seed 25 \
        --steps 3000 --val-steps 1000,2000,3000
    # stage 25: the shipped AGNDC (the students' teacher) continued on DATA, the sheets and
    # the strut frames, stage 14's recipe with the frames in place of the spiky shapes
    continue_agndc "$agndc_v6" strut_agndc16 "$data,$sheets,$struts" \
        --lr 5e-5 --ema 0.995 --seed 17
    # stage 21: the shipped agndc_fast taught by the true targets instead of the teacher's
    # (its verdict read at steps 1,000 and 2,000, where it was stopped)
    generate "$layered" -n 300 --seed0 60000 --layered 1.0
    stage student_true16 --data "$data,$sheets,$layered" \
        --init agndc_core/weights/agndc_student.safetensors --model "$student_config" \
        --steps 3000,0,0 --lr 1.25e-4 --ema 0.99 --seed 26 --val-steps 1000,2000,3000
    # stage 28: stage 23 with the strut frames on their true targets (the rest still the
    # teacher's): the student's bars closer, the thin sheets farther
    distil "$data" "${data}_distilled"
    distil "$sheets" "${sheets}_distilled"
    stage student_struts16_true \
        --data "${data}_distilled,${sheets}_distilled,${struts}" \
        --init agndc_core/weights/agndc_student.safetensors --model "$student_config" \
        --steps 2000,0,0 --lr 6.25e-5 --ema 0.99 --seed 27 --val-steps 1000,2000
    # stage 27: stage 25 (the shipped AGNDC on DATA, the sheets and the strut frames) at three
    # times its learning rate, the same seed and crops: whether the full cascade learns the
    # bars when it is let move as far as UNDC did
    continue_agndc "$agndc_v6" strut_agndc16_lr15 "$data,$sheets,$struts" \
        --lr 1.5e-4 --ema 0.995 --seed 17
    # stage 29: stage 27's step 400 continued at a third of its learning rate on the same
    # data: the centred gains given back, the softer edges kept
    stage strut_agndc16_lr15_cont --data "$data,$sheets,$struts" \
        --init "$runs/strut_agndc16_lr15/step-000400.safetensors" --model "$shipped_config" \
        --lr 5e-5 --ema 0.995 --seed 18 --steps 800,0,0 --val-steps 400,800
    # stage 30: stage 27 with another seed: the shifted grids' loss and the softer edges come
    # back, the centred and sheet gains do not (they were stage 27's crops')
    continue_agndc "$agndc_v6" strut_agndc16_lr15_seed19 "$data,$sheets,$struts" \
        --lr 1.5e-4 --ema 0.995 --seed 19
    # stage 31: stage 27 (same seed and crops) with crease and corner cells weighted 5x in the
    # vertex loss (--crease-weight 4); stage 32 the same with stage 30's seed; stage 33 stage 16
    # with it. The weight costs the thin sheets 0.15-0.33 against the same crops without it
    # (docs/experiments/thin-struts.md); stages 32 and 33 were judged at their step 400
    continue_agndc "$agndc_v6" strut_agndc16_lr15_crease4 "$data,$sheets,$struts" \
        --lr 1.5e-4 --ema 0.995 --seed 17 --crease-weight 4
    continue_agndc "$agndc_v6" strut_agndc16_lr15_crease4_seed19 "$data,$sheets,$struts" \
        --lr 1.5e-4 --ema 0.995 --seed 19 --crease-weight 4
    continue_agndc "$agndc_v6" layer_agndc16_crease4 "$data,$sheets,$layered" \
        --lr 5e-5 --ema 0.995 --seed 17 --crease-weight 4
    # stage 17: stage 16 again with another seed, whether its gain holds
    continue_agndc "$agndc_v6" layer_agndc16_seed19 "$data,$sheets,$layered" \
        --lr 5e-5 --ema 0.995 --seed 19
    # stage 34: stage 16 with a third seed (23)
    continue_agndc "$agndc_v6" layer_agndc16_seed23 "$data,$sheets,$layered" \
        --lr 5e-5 --ema 0.995 --seed 23
    ;;
history)
    stage bt_agndc16_long --lr 1e-3 --seed 5 --steps 3000,100,100 --binary-targets \
        --val-steps 3000
    stage dt_agndc16_cont --init "$runs/bt_agndc16_long/step-003000.safetensors" --lr 5e-4 \
        --seed 6 --steps 2400,0,0
    generate "$wrinkled" -n 900 --seed0 10000 --wrinkled 0.5
    stage wr_agndc16 --data "$wrinkled" --init agndc_core/weights/agndc.safetensors \
        --model "$shipped_config" --lr 2e-4 --ema 0.99 --seed 7 --steps 6000,0,0 \
        --val-steps 1000,2000,3000,4000,5000,6000
    generate "$sheets" -n 200 --seed0 20000 --sheets 1.0
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
        --model "$shipped_config" --lr 5e-5 --ema 0.999 --seed 8 --steps 6000,0,0 \
        --val-steps 1000,2000,3000,4000,5000,6000
    # stage 18: the UNDC shipped before it continued on DATA and the wrinkled shapes at half the
    # learning rate that trained it: the shipped undc (docs/experiments/wrinkled-surfaces.md)
    stage undc_wrinkled16 --undc --model '{"width": 16}' --data "$data,$wrinkled" \
        --init agndc_core/weights/undc.safetensors --lr 5e-4 --ema 0.995 --seed 23 \
        --steps 3000 --val-steps 1000,2000,3000
    # stage 16: stage 10's recipe with 300 layered parts added (train-data --layered 1.0); its
    # step 400 is the shipped agndc
    generate "$layered" -n 300 --seed0 60000 --layered 1.0
    continue_agndc "$agndc_v6" layer_agndc16 "$data,$sheets,$layered" \
        --lr 5e-5 --ema 0.995 --seed 17
    ;;
undc)
    stage bt_undc16_long --undc --model '{"width": 16}' --lr 1e-3 --seed 5 --steps 3000 \
        --binary-targets --val-steps 3000
    stage dt_undc16_cont --undc --model '{"width": 16}' \
        --init "$runs/bt_undc16_long/step-003000.safetensors" --lr 5e-4 --seed 6 --steps 2400
    ;;
*)
    echo "cpu_lineage.sh: the third argument is current, concluded, history or undc," \
        "not '$which'" >&2
    exit 2
    ;;
esac
