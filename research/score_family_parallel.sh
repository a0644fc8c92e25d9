#!/usr/bin/env bash
# The validation family scored on many cores at once (a GPU machine's 16), a checkpoint beside the
# shipped weights, centred at 64^3, grid alone, 30,000 samples per surface: the frame
# research/score_validation.sh calls "64", the same shapes and the same numbers, in parallel.
#
#   bash research/score_family_parallel.sh VAL OUT SHARDS [CHECKPOINT]
#
# VAL/famK (K < SHARDS) holds shard K of the family: `agndc val-data` from seed 2,000,000 + K*48/SHARDS
# (a shape depends on its seed alone, so the shards together are the 48 shapes of `agndc val-data
# -n 48`), made once. Without CHECKPOINT: the shipped weights with marching cubes and
# oracle_binary (the reference) into OUT/shipped/rows.csv. With it: that checkpoint into
# OUT/NAME/rows.csv (NAME: its file name's stem) and its comparison with the reference
# (research/compare_rows.py: CD, EF1 and the shares of the MC->oracle_binary headroom per class),
# printed and written to OUT/NAME.md. Each shard's eval is one process on one thread.
# AGNDC_PYTHON: the Python to run (default .venv/bin/python here, python3 where there is none).
set -euo pipefail
val=${1:?validation folder}; out=${2:?output folder}; shards=${3:?number of shards}
checkpoint=${4:-}
cd "$(dirname "$0")/.."
py=${AGNDC_PYTHON:-$([ -x .venv/bin/python ] && echo .venv/bin/python || echo python3)}
total=${AGNDC_FAMILY_SIZE:-48}  # fewer shapes only to check this script
(( total % shards == 0 )) || { echo "SHARDS must divide $total" >&2; exit 2; }
per=$(( total / shards ))
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONUNBUFFERED=1
pids=()
for (( k = 0; k < shards; k++ )); do
    [[ -f $val/fam$k/MANIFEST.csv ]] || "$py" -m agndc_core.cli val-data -o "$val/fam$k" \
        -n "$per" --seed0 $(( 2000000 + k * per )) --workers 1 >/dev/null 2>&1 &
    pids+=($!)
done
for pid in "${pids[@]}"; do wait "$pid"; done
if [[ -n $checkpoint ]]; then
    name=$(basename "$checkpoint" .safetensors)
    methods=(--methods agndc --checkpoint "agndc=$checkpoint")
else
    name=shipped
    methods=(--methods mc,oracle_binary,agndc)
fi
dest=$out/$name
mkdir -p "$dest"
pids=()
for (( k = 0; k < shards; k++ )); do
    "$py" -m agndc_core.cli eval "$val/fam$k" --res 64 "${methods[@]}" --samples 30000 \
        -o "$dest/part$k" >"$dest/part$k.log" 2>&1 &
    pids+=($!)
done
failed=0
for pid in "${pids[@]}"; do wait "$pid" || failed=1; done
(( failed == 0 )) || { tail -n 5 "$dest"/part*.log >&2; exit 1; }
# the shards' rows in one table, in seed order (one header)
head -n 1 "$dest/part0/rows.csv" >"$dest/rows.csv"
for (( k = 0; k < shards; k++ )); do tail -n +2 "$dest/part$k/rows.csv" >>"$dest/rows.csv"; done
if [[ -n $checkpoint ]]; then
    if [[ -f $out/shipped/rows.csv ]]; then
        "$py" research/compare_rows.py "$out/shipped/rows.csv" "$dest/rows.csv" --labels "$name" \
            | tee "$out/$name.md"
    else
        echo "no reference $out/shipped/rows.csv: score the shipped weights first" >&2
        exit 1
    fi
fi
