#!/usr/bin/env bash
# The stereo-video test sequences: built with `jem degrade --frames` from MiddEval3 trainingQ scenes and with
# `jem synth --frames`, seeded, so every machine builds the same frames. Nothing is written into the data set.
#
# Usage: scripts/video-sequences.sh OUT [--frames N] [--scenes "A B ..."]
#   OUT        folder to build the sequences in (created; each sequence a sub-folder, skipped if it exists)
#   --frames   frames per sequence (default 10)
#   --scenes   trainingQ scenes (default "Adirondack ArtL Motorcycle Teddy")
#
# Sequences (folder names): q-static-SCENE (clean, 3 frames), q-noise{4,6,8}-SCENE (static camera, fresh Gaussian
# noise of that sigma each frame, seed 1), q-pan-SCENE (a window sliding 3 px per frame across the pair: a panning
# camera, exact ground truth), s-{static,pan,dolly,object,cut} (synthetic, 320x240, ndisp 48, seed 1) and
# s-noise6 (synthetic static, noise sigma 6).
#
# Environment: JEM (the binary; default target/release/jem), JEM_DATA (the folder holding MiddEval3/trainingQ;
# default ../shared/middlebury).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
out=${1:?usage: scripts/video-sequences.sh OUT [--frames N] [--scenes "A B"]}
shift
frames=10
scenes="Adirondack ArtL Motorcycle Teddy"
while [[ $# -gt 0 ]]; do
    case $1 in
        --frames) frames=${2:?}; shift 2 ;;
        --scenes) scenes=${2:?}; shift 2 ;;
        *) echo "error: unknown option $1" >&2; exit 2 ;;
    esac
done
jem=${JEM:-$root/target/release/jem}
train=${JEM_DATA:-$root/../shared/middlebury}/MiddEval3/trainingQ
[[ -d $train ]] || { echo "error: no MiddEval3/trainingQ (set JEM_DATA)" >&2; exit 2; }
mkdir -p "$out"

make() { # NAME ARGS...: build one sequence unless it exists
    local name=$1; shift
    [[ -d $out/$name/left ]] && return 0
    # The output folder goes last for synth, after SRC for degrade.
    if [[ $1 == degrade ]]; then "$jem" -q degrade "$2" "$out/$name" "${@:3}"; else "$jem" -q "$@" "$out/$name"; fi
}
for s in $scenes; do
    make "q-static-$s" degrade "$train/$s" --recipe none --frames 3
    for sigma in 4 6 8; do
        make "q-noise$sigma-$s" degrade "$train/$s" --recipe "noise:$sigma" --frames "$frames" --seed 1
    done
    make "q-pan-$s" degrade "$train/$s" --recipe none --frames "$frames" --pan 3
done
for motion in static pan dolly object cut; do
    make "s-$motion" synth --frames "$frames" --motion "$motion" --seed 1
done
make s-noise6 synth --frames "$frames" --motion static --noise 6 --seed 1
ls "$out"
