#!/usr/bin/env bash
# One resumable training chunk ON THE LENT GPU MACHINE (device tool `run`, <= 10 minutes a call).
#
#   bash scripts/gpu_chunk.sh RUN MINUTES [extra `agndc train` options...]
#
# Installs the carried wheels (.whl/), regenerates the procedural data with all 16 cores (the
# machine starts bare every call; generation is seeded, so every chunk sees the same samples),
# resumes runs/RUN from its carried state shards, trains for MINUTES of wall time on CUDA with
# bf16 autocast, and copies the state (shards <= 15 MiB each) and run.json to $OUT. The device
# call names `runs/RUN` and `.whl` in `carry`; copy the returned files back into runs/RUN before
# the next call. docs/training.md has the whole runbook.
set -euo pipefail
run=${1:?run name}; minutes=${2:?minutes of training}; shift 2
cd "$(dirname "$0")/.."
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl
export PYTHONPATH="/tmp/site:$PWD" PYTHONUNBUFFERED=1
agndc() { python3 -m agndc_core.cli "$@"; }
data=/tmp/agndc_data
start=$(date +%s)
agndc train-data -o "$data/train" -n "${AGNDC_SAMPLES:-5000}" --workers 16
agndc train-data -o "$data/val" -n 24 --seed0 1000000 --workers 16
echo "data: $(( $(date +%s) - start )) s"
agndc train --data "$data/train" --val "$data/val" -o "runs/$run" --device cuda --workers 8 \
    --threads 4 --resume --max-minutes "$minutes" "$@"
if [ -n "${OUT:-}" ]; then
    cp "runs/$run"/run.json "runs/$run"/state-*.safetensors "$OUT"/
    cp "runs/$run"/final.* "$OUT"/ 2>/dev/null || true
fi
