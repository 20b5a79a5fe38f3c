#!/usr/bin/env bash
# The data of docs/RESULTS.md "Native resolution and noise", built from MiddEval3 trainingQ (nothing is downloaded
# but the two trainingH views, from a public repository that ships them as demo images):
#   OUT/n1, n2, n3/trainingQ   trainingQ with Gaussian noise of σ 1, 2, 3 per channel (`jem degrade noise:S`)
#   OUT/x2/trainingH           trainingQ upscaled 2× (views bicubic, truth ×2 by pixel replication, masks nearest;
#                              examples/upscale.rs), then noise σ 1.3 at the new size; scored in H pixels (×2)
#   OUT/x4/trainingF           the same 4×, scored in full-size pixels (×1)
#   OUT/x2c/trainingH, x4c/trainingF   the same enlargements without the noise
#   OUT/H/trainingH            MiddEval3 trainingH im0/im1 of Motorcycle and PlaytableP (no truth; calib.txt from
#                              trainingQ's with the sizes and range ×2), when IGEV is given (see below)
#   OUT/HQ/trainingQ           links to trainingQ's truth for those two, where scripts/h-on-q.py writes the H
#                              answers brought to the Q grid
#
# Usage: scripts/native-set.sh OUT [IGEV]
#   IGEV: a clone (or bare copy) of github.com/gangweiX/IGEV, whose
#         IGEV-Stereo/demo-imgs/{Motorcycle,PlaytableP}/im{0,1}.png are MiddEval3 trainingH views.
# Environment: JEM_DATA (folder holding MiddEval3/trainingQ; default ../shared/middlebury), JEM (the binary;
# default target/release/jem). OUT must not exist. Seeded: every machine makes the same images.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
out=${1:?usage: scripts/native-set.sh OUT [IGEV]}
igev=${2:-}
data=${JEM_DATA:-$root/../shared/middlebury}
q=$data/MiddEval3/trainingQ
jem=${JEM:-$root/target/release/jem}
[[ -d $q ]] || { echo "error: no MiddEval3/trainingQ under $data (set JEM_DATA)" >&2; exit 2; }
[[ -e $out ]] && { echo "error: $out exists; give a new folder" >&2; exit 2; }
[[ -x $jem ]] || { echo "error: no jem binary at $jem (cargo build --release, or set JEM)" >&2; exit 2; }
(cd "$root" && cargo build --release --locked --example upscale --quiet)
upscale=$root/target/release/examples/upscale
mkdir -p "$out"
scenes=$(cd "$q" && ls -d */ | tr -d /)

for s in 1 2 3; do
    "$jem" degrade "$q" "$out/n$s/trainingQ" --recipe "noise:$s" --seed 1 --quiet
done
tmp=$(mktemp -d "$out/.tmp.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
for k in 2 4; do
    split=$([[ $k = 2 ]] && echo trainingH || echo trainingF)
    # shellcheck disable=SC2086 # the scene names are words
    "$upscale" "$q" "$tmp/x$k" $k $scenes > /dev/null
    "$jem" degrade "$tmp/x$k" "$out/x$k/$split" --recipe noise:1.3 --seed 1 --quiet
    mkdir -p "$out/x${k}c"
    mv "$tmp/x$k" "$out/x${k}c/$split"
done

if [[ -n $igev ]]; then
    for s in Motorcycle PlaytableP; do
        mkdir -p "$out/H/trainingH/$s" "$out/HQ/trainingQ/$s"
        for v in im0 im1; do
            git -C "$igev" show "HEAD:IGEV-Stereo/demo-imgs/$s/$v.png" > "$out/H/trainingH/$s/$v.png"
        done
        awk -F= 'BEGIN { OFS = "=" } /^(ndisp|width|height|doffs|vmin|vmax)=/ { $2 = $2 * 2 } { print }' \
            "$q/$s/calib.txt" > "$out/H/trainingH/$s/calib.txt"
        for f in im0.png im1.png calib.txt disp0GT.pfm mask0nocc.png; do
            ln -s "$q/$s/$f" "$out/HQ/trainingQ/$s/$f"
        done
    done
fi
echo "wrote $out: n1 n2 n3 (trainingQ + noise), x2 (trainingH), x4 (trainingF), x2c x4c (no noise)${igev:+, H and HQ}"
