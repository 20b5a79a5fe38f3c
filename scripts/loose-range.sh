#!/usr/bin/env bash
# A MiddEval3 tree whose calib.txt files state ndisp = the image width, as ETH3D's do: the case where the stated
# range is no real bound and jem measures the range on the pair instead (src/setup/range.rs).
#
# Usage: scripts/loose-range.sh SRC OUT
#   SRC  a MiddEval3 split (e.g. $JEM_DATA/MiddEval3/trainingQ): scene folders with im0.png, im1.png, calib.txt
#   OUT  a folder that must not exist yet; it gets one folder per scene with symbolic links to SRC's images,
#        disp0GT.pfm and mask0nocc.png (when present), and a copy of calib.txt with ndisp=<width>.
# Nothing in SRC is written. OUT is built under a hidden name beside it and renamed when complete.
#
# Then, for example (the time and the accuracy against the stated range):
#   jem batch OUT --alg Loose && jem eval OUT --alg Loose
#   jem batch SRC-copy --alg Stated && jem eval SRC-copy --alg Stated
set -euo pipefail

[[ $# -eq 2 ]] || { sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
src=$(cd "$1" && pwd)
out=$2
[[ -e $out ]] && { echo "error: $out exists; give a new folder" >&2; exit 2; }
parent=$(dirname "$out")
[[ -d $parent ]] || { echo "error: no folder $parent" >&2; exit 2; }
tmp=$parent/.$(basename "$out").partial.$$
mkdir "$tmp"
trap 'rm -rf -- "$tmp"' EXIT

n=0
for dir in "$src"/*/; do
    scene=$(basename "$dir")
    calib=$dir/calib.txt
    [[ -f $calib && -f $dir/im0.png && -f $dir/im1.png ]] || continue
    width=$(sed -n 's/^width=\([0-9]*\).*/\1/p' "$calib")
    [[ -n $width ]] || { echo "error: $calib has no width" >&2; exit 1; }
    mkdir "$tmp/$scene"
    for f in im0.png im1.png disp0GT.pfm mask0nocc.png; do
        [[ -f $dir/$f ]] && ln -s "$dir$f" "$tmp/$scene/$f"
    done
    sed "s/^ndisp=.*/ndisp=$width/" "$calib" > "$tmp/$scene/calib.txt"
    n=$((n + 1))
done
[[ $n -gt 0 ]] || { echo "error: no MiddEval3 scene folders under $src" >&2; exit 1; }
mv "$tmp" "$out"
trap - EXIT
echo "$n scenes in $out (ndisp = width)"
