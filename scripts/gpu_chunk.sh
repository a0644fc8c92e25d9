#!/usr/bin/env bash
# One call of the device tool (`run`, <= 10 minutes) on the lent GPU machine, for a training run
# that outlives the call:
#
#   bash scripts/gpu_chunk.sh RUN SECONDS [extra `agndc train` options...]
#
# The first call on a machine installs the carried wheels (.whl/), generates the procedural data
# with all 16 cores (seeded: every machine makes the same samples; AGNDC_SAMPLES, default 5000),
# and starts `agndc train --device cuda --resume` in its own process session, so it keeps
# training between calls while the machine is held. Its run folder is /tmp/agndc_runs/RUN,
# seeded from the carried runs/RUN (the state of an earlier machine) when it is new. Every call
# then waits SECONDS (or until the trainer exits), copies run.json, the state shards (<= 15 MiB
# each), final.* and the log to $OUT, and prints the log's tail. Later calls on the same machine
# only wait and copy (their train options are ignored); on a fresh machine they resume. A call
# without train options never starts a trainer; none starts once final.safetensors exists.
# Carry `.whl` and `runs/RUN`; copy the returned files into runs/RUN after each call.
# AGNDC_SMOKE=1: instead, a 30+10+10-step run on the held-out samples (checks CUDA, prints step time).
# AGNDC_RESOLUTIONS=LO,HI: the training shapes' voxels on their longest side (default 32,128);
# each range has its own data folder. The held-out samples stay 32-128 (comparable runs).
set -euo pipefail
run=${1:?run name}; seconds=${2:?seconds to wait}; shift 2
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
data=/tmp/agndc_data
resolutions=${AGNDC_RESOLUTIONS:-32,128}
train="$data/train_${resolutions/,/-}"
work=/tmp/agndc_runs/$run
pidfile=/tmp/agndc_runs/$run.pid
mkdir -p /tmp/agndc_runs
agndc train-data -o "$data/val" -n 24 --seed0 1000000 --workers 16 2>/dev/null
genpid=/tmp/agndc_runs/datagen.pid
if [ -n "${AGNDC_SMOKE:-}" ]; then
    # the training data is generated in the background meanwhile, for the next call
    if ! alive "$genpid"; then
        setsid nohup "$py" -m agndc_core.cli train-data -o "$train" --resolutions "$resolutions" \
            -n "${AGNDC_SAMPLES:-5000}" --workers 14 >/tmp/agndc_runs/datagen.log 2>&1 </dev/null &
        echo $! >"$genpid"
    fi
    rm -rf /tmp/agndc_smoke
    agndc train --data "$data/val" -o /tmp/agndc_smoke --device cuda --workers 8 --threads 4 \
        --steps 30,10,10 "$@" 2>&1 | tr '\r' '\n' >/tmp/agndc_runs/smoke.log || true
    grep -q "^checkpoint" /tmp/agndc_runs/smoke.log || { tail -n 30 /tmp/agndc_runs/smoke.log; exit 1; }
    grep -E "100%.*=|^checkpoint" /tmp/agndc_runs/smoke.log
    "$py" -c "import json; t = json.load(open('/tmp/agndc_smoke/final.json'))['training']; \
print('step time', t['train_seconds'], 's, of which waiting for batches', t['data_wait_seconds'], 's')"
    exit 0
fi
if [ ! -f "$work/final.safetensors" ] && [ "$#" -gt 0 ] && ! alive "$pidfile"; then
    while alive "$genpid"; do sleep 2; done
    agndc train-data -o "$train" --resolutions "$resolutions" -n "${AGNDC_SAMPLES:-5000}" \
        --workers 16 2>/dev/null
    echo "data ready after $(( $(date +%s) - start )) s: $(ls "$train" | wc -l) samples"
    if [ ! -f "$work/run.json" ] && [ -d "runs/$run" ]; then
        mkdir -p "$work" && cp -r "runs/$run"/. "$work"/
    fi
    mkdir -p "$work"
    setsid nohup "$py" -m agndc_core.cli train --data "$train" --val "$data/val" \
        -o "$work" --device cuda --workers 12 --threads 4 --resume "$@" \
        >>"$work/train.log" 2>&1 </dev/null &
    echo $! >"$pidfile"
    echo "trainer started: pid $(cat "$pidfile")"
fi
while [ $(( $(date +%s) - start )) -lt "$seconds" ] && alive "$pidfile"; do
    sleep 5
done
if [ -n "${OUT:-}" ]; then
    # run.json first: a save landing between the copies leaves weights newer than its step
    cp "$work"/run.json "$OUT"/ 2>/dev/null || true
    cp "$work"/state-*.safetensors "$work"/train.log "$OUT"/ 2>/dev/null || true
    cp "$work"/final.* "$OUT"/ 2>/dev/null || true
fi
alive "$pidfile" && echo "trainer running" || echo "trainer not running"
# the log may not exist yet, or hold no line yet (grep then fails): neither is an error here
[ -f "$work/train.log" ] && { tr '\r' '\n' <"$work/train.log" | grep -v '^\s*$' | tail -n 8 || true; }
exit 0
