#!/usr/bin/env bash
# Runs `jem sequence` (the temporal model; `-- --independent` for each frame alone) on every test sequence of
# scripts/video-sequences.sh and scores each with `jem eval` (JSON beside the results). Resumable: frames already
# written are skipped by jem itself.
#
# Usage: scripts/video-run.sh SEQS RESULTS [--only GLOB] [-- JEM_SEQUENCE_ARGS...]
#   SEQS      the folder scripts/video-sequences.sh built
#   RESULTS   where RESULTS/NAME/ (the maps, times.txt) and RESULTS/NAME.json (the scores) go
#   --only    only the sequences whose name matches GLOB (e.g. 'q-noise6-*')
#   after --   more arguments for `jem sequence` (e.g. --independent, or --set meanfield.iterations=2)
# Sequences made from trainingQ (q-*) are scored in full-resolution px (--scale 4), synthetic ones (s-*) in px.
#
# Environment: JEM (the binary; default target/release/jem).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
seqs=${1:?usage: scripts/video-run.sh SEQS RESULTS [--only GLOB] [-- ARGS]}
results=${2:?usage: scripts/video-run.sh SEQS RESULTS [--only GLOB] [-- ARGS]}
shift 2
only='*'
extra=()
while [[ $# -gt 0 ]]; do
    case $1 in
        --only) only=${2:?}; shift 2 ;;
        --) shift; extra=("$@"); break ;;
        *) echo "error: unknown option $1" >&2; exit 2 ;;
    esac
done
jem=${JEM:-$root/target/release/jem}
mkdir -p "$results"
for dir in "$seqs"/*/; do
    name=$(basename "$dir")
    # shellcheck disable=SC2053
    [[ $name == $only ]] || continue
    scale=1
    [[ $name == q-* ]] && scale=4
    "$jem" -q sequence "$dir" -o "$results/$name" ${extra[@]+"${extra[@]}"}
    "$jem" -q eval "$results/$name" --scale "$scale" --format json > "$results/$name.json"
    echo "$name done" >&2
done
