#!/usr/bin/env bash
# Downloads the Middlebury 2014 stereo benchmark (MiddEval3) at quarter resolution: the input pairs of the training
# and test scenes (MiddEval3-data-Q.zip) and the training ground truth (MiddEval3-GT0-Q.zip), and unzips both into
# one folder, so that DIR/MiddEval3/trainingQ/<Scene>/ holds im0.png, im1.png, calib.txt, disp0GT.pfm and
# mask0nocc.png.
#
# Usage: scripts/get-middlebury.sh [DIR]    (default DIR: ./data)
# Needs curl or wget, and unzip. Existing files are overwritten; the zips are kept in DIR for re-runs.
set -euo pipefail

BASE_URL="https://vision.middlebury.edu/stereo/submit3/zip"
ZIPS=(MiddEval3-data-Q.zip MiddEval3-GT0-Q.zip)

usage() {
    sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'
}

case "${1:-}" in
    -h | --help)
        usage
        exit 0
        ;;
esac
if [ "$#" -gt 1 ]; then
    usage >&2
    exit 2
fi
dir="${1:-./data}"

if command -v curl >/dev/null 2>&1; then
    fetch() { curl --fail --location --show-error --progress-bar --output "$2" "$1"; }
elif command -v wget >/dev/null 2>&1; then
    fetch() { wget --quiet --show-progress --output-document="$2" "$1"; }
else
    echo "error: neither curl nor wget is installed; install one of them (e.g. apt-get install curl)" >&2
    exit 1
fi
if ! command -v unzip >/dev/null 2>&1; then
    echo "error: unzip is not installed; install it (e.g. apt-get install unzip)" >&2
    exit 1
fi

mkdir -p "$dir"
for zip in "${ZIPS[@]}"; do
    if [ -s "$dir/$zip" ]; then
        echo "using the existing $dir/$zip"
    else
        echo "downloading $BASE_URL/$zip -> $dir/$zip"
        fetch "$BASE_URL/$zip" "$dir/$zip.part"
        mv "$dir/$zip.part" "$dir/$zip"
    fi
    echo "unzipping $dir/$zip into $dir/"
    unzip -q -o "$dir/$zip" -d "$dir"
done

echo "done: training scenes in $dir/MiddEval3/trainingQ/, test scenes in $dir/MiddEval3/testQ/"
echo "try: jem $dir/MiddEval3/trainingQ/Teddy/im0.png $dir/MiddEval3/trainingQ/Teddy/im1.png -o teddy.pfm"
