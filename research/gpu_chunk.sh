#!/usr/bin/env bash
# One command (<= 10 minutes) on a GPU machine, for a training run that outlives the command:
#
#   bash research/gpu_chunk.sh RUN SECONDS [extra `agndc train` options...]
#
# The first call on a machine installs the wheels sent with it (.whl/), generates the procedural
# data with all 16 cores (seeded: every machine makes the same samples; AGNDC_SAMPLES, default
# 5000), and starts `agndc train --device cuda --resume` in its own process session, so it keeps
# training between calls while the machine runs. Its run folder is /tmp/agndc_runs/RUN, seeded
# from runs/RUN sent with the call (the state of an earlier machine) when it is new. Every call
# then waits SECONDS (or until the trainer exits), copies run.json, the state shards (<= 15 MiB
# each), final.*, the log and steps.tar (the --val-steps checkpoints) to $OUT, and prints the
# log's tail. Later calls on the same machine only wait and copy (their train options are
# ignored); on a fresh machine they resume. A call without train options never starts a
# trainer; none starts once final.safetensors exists.
# Send `.whl` and `runs/RUN`; copy the returned files into runs/RUN after each call.
# AGNDC_SMOKE=1: instead, a 30+10+10-step run on the held-out samples (checks CUDA, prints step time).
# AGNDC_RESOLUTIONS=LO,HI: the training shapes' voxels on their longest side (default 32,128);
# each range has its own data folder. The held-out samples stay 32-128 (comparable runs).
# AGNDC_WRINKLED=SHARE: the share of organic and smooth shapes with fine wrinkles (`agndc
# train-data --wrinkled`, default 0.5; docs/experiments/wrinkled-training.md), its own folder too.
# AGNDC_SHEETS=SHARE: the share of thin sheets (`agndc train-data --sheets`, default 0.15: 18 %
# of the samples gained 3.4 points of the validation family's headroom on centred grids over a
# control at equal steps, docs/experiments/sheet-training.md), its own folder too.
# AGNDC_LAYERED=SHARE: the share of layered parts (caps, lids, stepped plates: `agndc train-data
# --layered`, default 0; the CPU lineage's stages 16-17 had 21 %, which gained on the thin
# sheets with both seeds, docs/experiments/layered-parts.md), its own folder too.
# AGNDC_STRUTS=SHARE: the share of thin-strut frames (pavilions on columns, space frames,
# railings, wire rings: `agndc train-data --struts`, default 0; docs/experiments/thin-struts.md),
# its own folder too.
# AGNDC_SCORE=SHARDS (one run only): the run's newest checkpoint (final, else the last --val-steps
# one) scored on the validation family and the thin sheets beside the shipped weights once the
# wait is over (research/score_validation_parallel.sh on SHARDS processes, a divisor of 24, e.g.
# 6: the shipped weights' rows are made while the trainer runs), the comparisons in
# $OUT/score.md (which then holds the benchmark's table too, in place of throughput.txt). Leave
# ~1-2 minutes of SECONDS' time for it after the trainer's --max-minutes.
# AGNDC_BENCH=MODE:BATCH,...: before the trainer starts, while the data is generated (12
# workers), benchmarks/bench_training_throughput.py times those variants (eager or a
# `--compile` mode, and a batch size; the first is the baseline) on the held-out samples and
# writes $OUT/throughput.txt (at most AGNDC_BENCH_SECONDS, default 240), for the width
# AGNDC_BENCH_WIDTH (default 16).
#
# A study, several runs side by side on the one GPU (a width-16 step is bound by launching
# kernels, not by the GPU, docs/experiments/step-times.md):
#
#   bash research/gpu_chunk.sh @STUDY SECONDS [common `agndc train` options...]
#
# STUDY is a file of lines "RUN [its own train options]" (# comments). Every run trains on the
# same data with the common options and then its own (the last of a repeated option wins),
# with 12 data-loader workers shared out. Each comes back as $OUT/RUN.tar (run.json, the log,
# final.* when done, and the state shards), split into RUN.tar.part0, part1, ... when it is
# 16 MiB or more: send `runs/RUN` and untar each into it (`cat RUN.tar* | tar -x -C
# runs/RUN`). Common options start the trainers, as for one run; without them a call only
# waits and copies.
set -euo pipefail
run=${1:?run name or @study file}; seconds=${2:?seconds to wait}; shift 2
cd "$(dirname "$0")/.."
start=$(date +%s)
# AGNDC_PYTHON: a Python that has every dependency already (a dry run here, on the CPU)
py=${AGNDC_PYTHON:-python3}
if [ -z "${AGNDC_PYTHON:-}" ]; then
    [ -d /tmp/site/manifold3d ] || python3 -m pip install -q --no-index --no-deps --no-compile \
        --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
    export PYTHONPATH="/tmp/site:$PWD"
fi
export PYTHONUNBUFFERED=1
agndc() { "$py" -m agndc_core.cli "$@"; }
alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }  # the process of a pid file
# tar_out NAME DIR FILES...: $OUT/NAME.tar of DIR's FILES. A file comes back only under 16 MiB:
# a larger tar (a wide model's state) comes back in parts, NAME.tar.part0, part1, ... (`cat
# NAME.tar.part* > NAME.tar`); at most 8 files come back in all
tar_out() {
    local name=$1 dir=$2
    shift 2
    (cd "$dir" && tar -cf "$OUT/$name.tar" "$@")
    if [ "$(stat -c %s "$OUT/$name.tar")" -ge $(( 16 * 1024 * 1024 )) ]; then
        split -b $(( 15 * 1024 * 1024 )) -d -a 1 "$OUT/$name.tar" "$OUT/$name.tar.part"
        rm "$OUT/$name.tar"
    fi
}
data=/tmp/agndc_data
resolutions=${AGNDC_RESOLUTIONS:-32,128}
wrinkled=${AGNDC_WRINKLED:-0.5}
sheets=${AGNDC_SHEETS:-0.15}
layered=${AGNDC_LAYERED:-0}
struts=${AGNDC_STRUTS:-0}
train="$data/train_${resolutions/,/-}_w${wrinkled}_s${sheets}_l${layered}_t$struts"
mkdir -p /tmp/agndc_runs
agndc train-data -o "$data/val" -n 24 --seed0 1000000 --workers 16 2>/dev/null
genpid=/tmp/agndc_runs/datagen.pid
# start_datagen WORKERS: the training data generated in the background (unless it already is);
# wait for it with `alive "$genpid"`
start_datagen() {
    alive "$genpid" && return 0
    setsid nohup "$py" -m agndc_core.cli train-data -o "$train" --resolutions "$resolutions" \
        --wrinkled "$wrinkled" --sheets "$sheets" --layered "$layered" --struts "$struts" \
        -n "${AGNDC_SAMPLES:-5000}" --workers "$1" \
        >/tmp/agndc_runs/datagen.log 2>&1 </dev/null &
    echo $! >"$genpid"
}
if [ -n "${AGNDC_SMOKE:-}" ]; then
    # the training data is generated in the background meanwhile, for the next call
    start_datagen 14
    rm -rf /tmp/agndc_smoke
    agndc train --data "$data/val" -o /tmp/agndc_smoke --device cuda --workers 8 --threads 4 \
        --steps 30,10,10 "$@" 2>&1 | tr '\r' '\n' >/tmp/agndc_runs/smoke.log || true
    grep -q "^checkpoint" /tmp/agndc_runs/smoke.log || { tail -n 30 /tmp/agndc_runs/smoke.log; exit 1; }
    grep -E "100%.*=|^checkpoint" /tmp/agndc_runs/smoke.log
    "$py" -c "import json; t = json.load(open('/tmp/agndc_smoke/final.json'))['training']; \
print('step time', t['train_seconds'], 's, of which waiting for batches', t['data_wait_seconds'], 's')"
    exit 0
fi
# the runs: RUN and its own options, one per line
if [ "${run#@}" != "$run" ]; then
    study=${run#@}
    runs=$(grep -v '^\s*\(#\|$\)' "$study")
else
    study=
    runs=$run
fi
names=$(printf '%s\n' "$runs" | awk '{print $1}')
count=$(printf '%s\n' "$names" | wc -l)
# 16 cores: 12 data-loader workers shared out, and the trainers' own threads
workers=$(( 12 / count > 2 ? 12 / count : 2 ))
threads=$(( count > 1 ? 2 : 4 ))
# whether RUN still has to be started on this machine (not finished, not running)
startable() {
    [ ! -f "/tmp/agndc_runs/$1/final.safetensors" ] && ! alive "/tmp/agndc_runs/$1.pid"
}
# one run's folder, pid file and start: start_run RUN [options...]
start_run() {
    local name=$1 work=/tmp/agndc_runs/$1 pidfile=/tmp/agndc_runs/$1.pid
    shift
    startable "$name" || return 0
    if [ ! -f "$work/run.json" ] && [ -d "runs/$name" ]; then
        mkdir -p "$work" && cp -r "runs/$name"/. "$work"/
    fi
    mkdir -p "$work"
    setsid nohup "$py" -m agndc_core.cli train --data "$train" --val "$data/val" \
        -o "$work" --device cuda --workers "$workers" --threads "$threads" --resume "$@" \
        >>"$work/train.log" 2>&1 </dev/null &
    echo $! >"$pidfile"
    echo "trainer $name started: pid $(cat "$pidfile")"
}
any_alive() {
    local name
    for name in $names; do
        alive "/tmp/agndc_runs/$name.pid" && return 0
    done
    return 1
}
need=0
for name in $names; do
    if startable "$name"; then need=1; fi
done
if [ "$#" -gt 0 ] && [ "$need" = 1 ]; then
    if [ -n "${AGNDC_BENCH:-}" ]; then
        # the data in the background on 12 cores; the benchmark's launching thread gets its own
        start_datagen 12
        timeout "${AGNDC_BENCH_SECONDS:-240}" "$py" benchmarks/bench_training_throughput.py \
            --data "$data/val" --device "${AGNDC_BENCH_DEVICE:-cuda}" --variants "$AGNDC_BENCH" \
            --width "${AGNDC_BENCH_WIDTH:-16}" --steps 20 --warmup 3 --threads 2 2>&1 \
            | tee "${OUT:-/tmp/agndc_runs}/throughput.txt" || true
    fi
    while alive "$genpid"; do sleep 2; done
    agndc train-data -o "$train" --resolutions "$resolutions" --wrinkled "$wrinkled" \
        --sheets "$sheets" --layered "$layered" --struts "$struts" -n "${AGNDC_SAMPLES:-5000}" \
        --workers 16 2>/dev/null
    echo "data ready after $(( $(date +%s) - start )) s: $(ls "$train" | wc -l) samples"
    while read -r name own; do
        # word splitting of the study line's options is intended (no quoting inside a line)
        # shellcheck disable=SC2086
        start_run "$name" "$@" $own
    done <<<"$runs"
fi
score=/tmp/agndc_score
sets="family sheets"
# score_sets [CHECKPOINT]: research/score_validation_parallel.sh on each set in turn
score_sets() {
    local set
    for set in $sets; do
        AGNDC_PYTHON="$py" bash research/score_validation_parallel.sh "$set" "$data/score" \
            "$score" "$AGNDC_SCORE" "$@" || return 1
    done
}
if [ -n "${AGNDC_SCORE:-}" ] && [ -z "$study" ] && [ ! -f "$score/sheets/shipped/rows.csv" ] \
        && ! alive "$score.pid"; then
    # the reference while the trainer runs: the sets' shards and the shipped weights' rows
    mkdir -p "$score"
    (score_sets) >"$score/shipped.log" 2>&1 </dev/null &
    echo $! >"$score.pid"
fi
while [ $(( $(date +%s) - start )) -lt "$seconds" ] && any_alive; do
    sleep 5
done
if [ -n "${AGNDC_SCORE:-}" ] && [ -z "$study" ] && [ -f "$score.pid" ]; then
    work=/tmp/agndc_runs/$run
    newest=$(ls "$work"/final.safetensors 2>/dev/null \
        || ls "$work"/step-*.safetensors 2>/dev/null | sort | tail -n 1 || true)
    while alive "$score.pid"; do sleep 2; done
    if [ -n "$newest" ] && [ -f "$score/sheets/shipped/rows.csv" ]; then
        echo "scoring $(basename "$newest") on the validation family and the thin sheets"
        stem=$(basename "$newest" .safetensors)
        if score_sets "$newest" >"$score/candidate.log" 2>&1; then
            for set in $sets; do
                printf '## %s, 64^3, centred\n\n' "$set"
                cat "$score/$set/$stem.md"
                echo
            done >"${OUT:-/tmp}/score.md"
            cat "${OUT:-/tmp}/score.md"
            # one file fewer of the 8 that come back: the benchmark's table joins the scores
            if [ -f "${OUT:-/tmp}/throughput.txt" ]; then
                { echo "## throughput"; echo; cat "${OUT:-/tmp}/throughput.txt"; } \
                    >>"${OUT:-/tmp}/score.md"
                rm "${OUT:-/tmp}/throughput.txt"
            fi
        else
            tail -n 5 "$score/candidate.log"
        fi
    else
        echo "no checkpoint or no reference to score"; tail -n 5 "$score/shipped.log" || true
    fi
fi
for name in $names; do
    work=/tmp/agndc_runs/$name
    [ -d "$work" ] || { echo "$name: no run folder"; continue; }
    if [ -n "${OUT:-}" ] && [ -z "$study" ]; then
        # run.json first: a save landing between the copies leaves weights newer than its step
        cp "$work"/run.json "$OUT"/ 2>/dev/null || true
        cp "$work"/state-*.safetensors "$work"/train.log "$OUT"/ 2>/dev/null || true
        cp "$work"/final.* "$OUT"/ 2>/dev/null || true
        # the --val-steps checkpoints, in one file (at most 8 files come back)
        if compgen -G "$work/step-*" >/dev/null; then
            # shellcheck disable=SC2046
            tar_out steps "$work" $(cd "$work" && ls step-*)
        fi
    elif [ -n "${OUT:-}" ]; then
        files=$(cd "$work" && ls run.json train.log final.* step-* state-*.safetensors \
            2>/dev/null || true)
        # shellcheck disable=SC2086
        tar_out "$name" "$work" $files
    fi
    alive "/tmp/agndc_runs/$name.pid" && echo "$name: trainer running" \
        || echo "$name: trainer not running"
    # the log may not exist yet, or hold no line yet (grep then fails): neither is an error here
    [ -f "$work/train.log" ] && { tr '\r' '\n' <"$work/train.log" | grep -v '^\s*$' \
        | tail -n "$([ -n "$study" ] && echo 3 || echo 8)" || true; }
done
exit 0
