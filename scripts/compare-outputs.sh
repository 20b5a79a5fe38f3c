#!/usr/bin/env bash
# Byte-identity check for refactors and speed work: runs two jem binaries with the same configs over MiddEval3
# trainingQ and compares every disparity map with `cmp`. Prints IDENTICAL, or each differing (config, scene), and
# exits 1 on any difference.
#
# Usage: scripts/compare-outputs.sh OLD_JEM NEW_JEM [CONFIG...]   (default: every configs/*.toml)
# Environment: JEM_DATA (folder holding MiddEval3/trainingQ; default ../shared/middlebury), WORK (scratch folder;
# default target/compare-outputs; results go into a mirror of links, never into the data folder),
# JEM_ARGS (extra flags given to both binaries' `batch`, split on spaces, e.g. JEM_ARGS="--max-memory 300M" for a
# tiled run), OLD_CONFIGS (a folder from which the old binary takes each config, by file name, instead of CONFIG
# itself: for configs whose keys were renamed since the old binary, e.g. copies made with
# `git show OLD_COMMIT:configs/X.toml`), REUSE_OLD=1 (keep the old binary's maps already in WORK from an earlier run
# with the same configs and JEM_ARGS, and run only the new binary).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
[[ $# -ge 2 ]] || { sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 2; }
old=$1; new=$2; shift 2
configs=("$@")
[[ ${#configs[@]} -gt 0 ]] || configs=("$root"/configs/*.toml)
data=${JEM_DATA:-$root/../shared/middlebury}
train=$data/MiddEval3/trainingQ
work=${WORK:-$root/target/compare-outputs}
read -r -a extra <<<"${JEM_ARGS:-}"
[[ -d $train ]] || { echo "error: no MiddEval3/trainingQ under $data (set JEM_DATA)" >&2; exit 2; }

for side in old new; do
    for scene in "$train"/*/; do
        s=$(basename "$scene")
        mkdir -p "$work/$side/$s"
        for f in im0.png im1.png calib.txt; do ln -sfn "$scene$f" "$work/$side/$s/$f"; done
    done
done
bad=0
for config in "${configs[@]}"; do
    alg=Cmp$(basename "$config" .toml | tr -cd 'A-Za-z0-9')
    for side in old new; do
        bin=$old; [[ $side == new ]] && bin=$new
        side_config=$config
        [[ $side == old && -n ${OLD_CONFIGS:-} ]] && side_config=$OLD_CONFIGS/$(basename "$config")
        [[ $side == old && ${REUSE_OLD:-} == 1 ]] && continue
        rm -f "$work/$side"/*/"disp0$alg.pfm"
        "$bin" batch "$work/$side" --alg "$alg" --config "$side_config" ${extra[@]+"${extra[@]}"} --quiet \
            >/dev/null || {
            echo "error: $side binary failed on $config" >&2
            bad=1
        }
    done
    for scene in "$work/old"/*/; do
        s=$(basename "$scene")
        cmp -s "$scene/disp0$alg.pfm" "$work/new/$s/disp0$alg.pfm" || { echo "DIFF $(basename "$config") $s"; bad=1; }
    done
done
if [[ $bad == 0 ]]; then
    echo "IDENTICAL (${#configs[@]} configs, every trainingQ scene${JEM_ARGS:+, JEM_ARGS=$JEM_ARGS})"
else
    echo "NOT IDENTICAL"
    exit 1
fi
