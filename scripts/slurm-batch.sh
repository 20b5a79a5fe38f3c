#!/usr/bin/env bash
# One task of a Slurm job array running `jem batch` over a data set: task I of N processes shard I/N of the
# sorted pair list (pair k goes to shard k mod N + 1), so the tasks share nothing and need no coordination.
# --skip-existing is always on: resubmitting the same array after a failure or a timeout only runs the pairs
# whose result is missing or incomplete. Results land where `jem batch` puts them (MiddEval3: in each scene
# folder; KITTI/ETH3D: results/NAME/SPLIT/ beside the data set, or --results, which the tasks share, each with its
# own lock), so one `jem eval` scores them all.
#
# Usage:  sbatch --array=1-N [sbatch options] scripts/slurm-batch.sh DIR... --alg NAME [jem batch options]
#   e.g.  sbatch --array=1-15 --cpus-per-task=4 --mem=4G scripts/slurm-batch.sh MiddEval3/trainingQ --alg Jem
#         sbatch --array=1-40 --cpus-per-task=4 --mem=8G scripts/slurm-batch.sh kitti2015/training --alg Jem
#   then  jem eval MiddEval3/trainingQ --alg Jem      (or: jem eval kitti2015/training --alg Jem)
#
# The array must be a contiguous range (1-N or 0-(N-1); a %limit is fine). Each task runs with
# --threads = its --cpus-per-task and --max-memory = 90 % of its --mem (unless the arguments give them), so
# jem waits for or refuses what the allocation cannot hold instead of being killed.
# Environment: JEM (the binary; default: jem on PATH, else target/release/jem of this checkout).
# Outside Slurm, set SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_MIN and SLURM_ARRAY_TASK_MAX yourself to run one task.
#
#SBATCH --job-name=jem-batch
#SBATCH --cpus-per-task=4
#SBATCH --mem=8G
#SBATCH --time=04:00:00
#SBATCH --output=jem-batch-%A_%a.log
set -euo pipefail

if [[ $# -eq 0 || $1 == -h || $1 == --help ]]; then
    sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'
    exit 0
fi
task=${SLURM_ARRAY_TASK_ID:?not an array task: submit with sbatch --array=1-N (see --help)}
first=${SLURM_ARRAY_TASK_MIN:?SLURM_ARRAY_TASK_MIN is not set}
last=${SLURM_ARRAY_TASK_MAX:?SLURM_ARRAY_TASK_MAX is not set}
count=$((last - first + 1))
if [[ -n ${SLURM_ARRAY_TASK_COUNT:-} && $SLURM_ARRAY_TASK_COUNT != "$count" ]]; then
    echo "error: the array must be a contiguous range (got $SLURM_ARRAY_TASK_COUNT tasks in $first-$last)" >&2
    exit 2
fi
index=$((task - first + 1))

if [[ -z ${JEM:-} ]]; then
    if command -v jem >/dev/null; then
        JEM=jem
    else
        JEM=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/target/release/jem
    fi
fi

extra=()
args=" $* "
if [[ $args != *" --threads "* && -n ${SLURM_CPUS_PER_TASK:-} ]]; then
    extra+=(--threads "$SLURM_CPUS_PER_TASK")
fi
if [[ $args != *" --max-memory "* ]]; then
    mem_mb=${SLURM_MEM_PER_NODE:-}
    if [[ -z $mem_mb && -n ${SLURM_MEM_PER_CPU:-} ]]; then
        mem_mb=$((SLURM_MEM_PER_CPU * ${SLURM_CPUS_PER_TASK:-1}))
    fi
    if [[ -n $mem_mb && $mem_mb -gt 0 ]]; then
        extra+=(--max-memory "$((mem_mb * 9 / 10))M")
    fi
fi

echo "task $task: shard $index/$count on $(hostname), $JEM batch $* ${extra[*]}" >&2
exec "$JEM" batch "$@" --shard "$index/$count" --skip-existing "${extra[@]}"
