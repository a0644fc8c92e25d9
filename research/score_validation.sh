#!/usr/bin/env bash
# Score an AGNDC checkpoint on the generated validation family, the thin sheets, the rows of
# spikes, the layered caps and the pin plates, on the frames a shipping decision needs
# (docs/training.md, "Evaluating"), and compare it with the shipped weights scored the same way:
#   bash research/score_validation.sh VAL OUT NAME [CHECKPOINT] [FRAMES]
# VAL holds family/, family_b/, sheets/, sheets_b/, struts/, spikes/, spikes_thin/, caps/ and
# pins/
# (made by `bash research/score_validation.sh VAL data`: agndc val-data, 48 shapes, 48 more from
# their own seeds (a second family, to check a choice made on the first), 24 sheets, 48 more
# sheets from their own seeds (the sheets are the noisiest frame), 36 thin-strut shapes;
# research/spike_rows.py, 12 rows of cones 2-6 and 12 of cones 0.8-2 voxels in radius at the
# base; research/layered_caps.py, 24 caps of layers about a voxel thick; research/axis_pins.py,
# 24 plates with pins, holes and shafts along the grid axes; ~1 min). NAME without
# a CHECKPOINT scores the shipped weights, together with marching cubes and oracle_binary (the
# reference; run it first, as NAME "shipped"). FRAMES, default "64 64s sheets sheets_s
# sheets_b": 64 / 128 the family centred, 64s / 128s on 3 shifted grids per shape, 64b the
# second family centred, sheets / sheets_s the sheets at 64^3, sheets_b the second set of
# sheets, struts the thin struts, spikes / spikes_thin the rows of cones at 64^3, caps the
# layered caps at 64^3, pins the pin plates at 64^3. A finished frame is skipped. Results:
# OUT/NAME/FRAME/rows.csv, then the comparison with OUT/shipped/FRAME.
# Evaluations use every core: beside the CPU lineage, run this under `taskset -c 0`.
set -euo pipefail
cd "$(dirname "$0")/.."
val=$1
agndc=.venv/bin/agndc
if [[ ${2:-} == data ]]; then  # the validation data, once
    [[ -f $val/family/MANIFEST.csv ]] || $agndc val-data -o "$val/family" -n 48
    [[ -f $val/family_b/MANIFEST.csv ]] || $agndc val-data -o "$val/family_b" -n 48 \
        --seed0 2000100
    [[ -f $val/sheets/MANIFEST.csv ]] || $agndc val-data --sheets -o "$val/sheets" -n 24
    [[ -f $val/sheets_b/MANIFEST.csv ]] || $agndc val-data --sheets -o "$val/sheets_b" \
        --seed0 3000100 -n 48
    [[ -f $val/struts/MANIFEST.csv ]] || $agndc val-data --struts -o "$val/struts" -n 36
    [[ -f $val/spikes/MANIFEST.csv ]] || .venv/bin/python research/spike_rows.py \
        -o "$val/spikes" -n 12
    [[ -f $val/spikes_thin/MANIFEST.csv ]] || .venv/bin/python research/spike_rows.py \
        -o "$val/spikes_thin" -n 12 --radius 0.8,2
    [[ -f $val/caps/MANIFEST.csv ]] || .venv/bin/python research/layered_caps.py \
        -o "$val/caps" -n 24
    [[ -f $val/pins/MANIFEST.csv ]] || .venv/bin/python research/axis_pins.py \
        -o "$val/pins" -n 24
    exit 0
fi
out=$2 name=$3
checkpoint=${4:-}
frames=${5:-64 64s sheets sheets_s sheets_b}
if [[ -n $checkpoint ]]; then
    methods=(--methods agndc --checkpoint "agndc=$checkpoint")
else
    methods=(--methods mc,oracle_binary,agndc)
fi
for frame in $frames; do
    case $frame in
        64) args=("$val/family" --res 64) ;;
        64s) args=("$val/family" --res 64 --shifts 3) ;;
        128) args=("$val/family" --res 128) ;;
        128s) args=("$val/family" --res 128 --shifts 3) ;;
        64b) args=("$val/family_b" --res 64) ;;
        sheets) args=("$val/sheets" --res 64) ;;
        sheets_s) args=("$val/sheets" --res 64 --shifts 3) ;;
        sheets_b) args=("$val/sheets_b" --res 64) ;;
        struts) args=("$val/struts" --res 64) ;;
        spikes) args=("$val/spikes" --res 64) ;;
        spikes_thin) args=("$val/spikes_thin" --res 64) ;;
        caps) args=("$val/caps" --res 64) ;;
        pins) args=("$val/pins" --res 64) ;;
        *) echo "unknown frame '$frame' (64 64s 128 128s 64b sheets sheets_s sheets_b struts" \
                "spikes spikes_thin caps pins)" >&2
           exit 2 ;;
    esac
    dest=$out/$name/$frame
    if [[ ! -f $dest/rows.csv ]]; then
        mkdir -p "$out/$name"
        $agndc eval "${args[@]}" "${methods[@]}" --samples 30000 -o "$dest" > "$dest.log" 2>&1 \
            || { cat "$dest.log" >&2; exit 1; }
    fi
    if [[ -n $checkpoint && -f $out/shipped/$frame/rows.csv ]]; then
        echo "## $frame"
        .venv/bin/python research/compare_rows.py "$out/shipped/$frame/rows.csv" "$dest/rows.csv" \
            --labels "$name"
    fi
done
