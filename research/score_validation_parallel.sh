#!/usr/bin/env bash
# The validation family or the thin sheets scored on many cores at once (a GPU machine's 16), a
# checkpoint beside the shipped weights, centred at 64^3, grid alone, 30,000 samples per
# surface: the frames research/score_validation.sh calls "64" and "sheets", the same shapes and
# the same numbers, in parallel.
#
#   bash research/score_validation_parallel.sh SET VAL OUT SHARDS [CHECKPOINT]
#
# SET: family (48 shapes, `agndc val-data` from seed 2,000,000) or sheets (24, `agndc val-data
# --sheets` from seed 3,000,000). VAL/SET/K (K < SHARDS) holds shard K: `agndc val-data` from
# the set's first seed + K*SIZE/SHARDS (a shape depends on its seed alone, so the shards
# together are the set's shapes), made once. Without CHECKPOINT: the shipped weights with
# marching cubes and oracle_binary (the reference) into OUT/SET/shipped/rows.csv. With it: that
# checkpoint into OUT/SET/NAME/rows.csv (NAME: its file name's stem) and its comparison with the
# reference (research/compare_rows.py: CD, EF1 and the shares of the MC->oracle_binary headroom
# per class), printed and written to OUT/SET/NAME.md. Each shard's eval is one process on one
# thread. AGNDC_PYTHON: the Python to run (default .venv/bin/python here, python3 where there
# is none).
set -euo pipefail
set=${1:?family or sheets}; val=${2:?validation folder}; out=${3:?output folder}
shards=${4:?number of shards}; checkpoint=${5:-}
cd "$(dirname "$0")/.."
py=${AGNDC_PYTHON:-$([ -x .venv/bin/python ] && echo .venv/bin/python || echo python3)}
case $set in
    family) total=48 seed0=2000000 kind=() ;;
    sheets) total=24 seed0=3000000 kind=(--sheets) ;;
    *) echo "SET: family or sheets, not '$set'" >&2; exit 2 ;;
esac
total=${AGNDC_SET_SIZE:-$total}  # fewer shapes only to check this script
(( total % shards == 0 )) || { echo "SHARDS must divide $total" >&2; exit 2; }
per=$(( total / shards ))
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONUNBUFFERED=1
pids=()
for (( k = 0; k < shards; k++ )); do
    [[ -f $val/$set/$k/MANIFEST.csv ]] || "$py" -m agndc_core.cli val-data "${kind[@]}" \
        -o "$val/$set/$k" -n "$per" --seed0 $(( seed0 + k * per )) --workers 1 >/dev/null 2>&1 &
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
dest=$out/$set/$name
mkdir -p "$dest"
pids=()
for (( k = 0; k < shards; k++ )); do
    "$py" -m agndc_core.cli eval "$val/$set/$k" --res 64 "${methods[@]}" --samples 30000 \
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
    if [[ -f $out/$set/shipped/rows.csv ]]; then
        "$py" research/compare_rows.py "$out/$set/shipped/rows.csv" "$dest/rows.csv" \
            --labels "$name" | tee "$out/$set/$name.md"
    else
        echo "no reference $out/$set/shipped/rows.csv: score the shipped weights first" >&2
        exit 1
    fi
fi
