# Shared by the resumable studies (research/learning_curve.sh, research/ablation.sh); source it after
# setting: runs (folder of the runs), common (train arguments of every run), dev (mesh folder).
# A finished run or evaluation is skipped, a stopped run continues (--resume).
agndc=.venv/bin/agndc

train() {  # name, then the run's own arguments; fails if a time cap stopped the run
    local name=$1; shift
    [[ -f $runs/$name/final.safetensors ]] && return 0
    local again=()
    [[ -f $runs/$name/run.json ]] && again=(--resume)
    "$agndc" train -o "$runs/$name" "${common[@]}" "$@" "${again[@]}"
    [[ -f $runs/$name/final.safetensors ]]  # stopped by the time cap: the caller stops too
}

score() {  # name, method[, tag, eval options]: every step checkpoint of the run on the dev
    # meshes at 64^3; a tag names a second scoring with other options (e.g. _unfiltered
    # --no-normal-filter), read back as the run "<name><tag>"
    local name=$1 method=$2 tag=${3:-}
    shift $(( $# < 3 ? $# : 3 ))
    for ckpt in "$runs/$name"/step-*.safetensors; do
        local out=$runs/eval_${name}${tag}_$(basename "$ckpt" .safetensors)
        [[ -f $out/rows.csv ]] && continue
        "$agndc" eval "$dev" --methods "$method" --checkpoint "$method=$ckpt" --res 64 -o "$out" "$@"
    done
}

both_scores() {  # name, method: as remeshed (the normal filter on, the default) and as
    # contoured (the network's own vertices, run "<name>_unfiltered")
    score "$1" "$2"
    score "$1" "$2" _unfiltered --no-normal-filter
}
