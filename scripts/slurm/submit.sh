#!/usr/bin/env bash
# Submits a split render as a job array of N parts plus a merge job that runs
# once every part has succeeded; prints the two job ids.
#
#   scripts/slurm/submit.sh N SCENE.json PARTS_DIR OUT.png [render flags...]
#
# Extra sbatch options (partition, time limit, ...) go in SBATCH_ARGS, e.g.
#   SBATCH_ARGS="--partition=short --time=00:30:00" scripts/slurm/submit.sh 16 ...
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
n=${1:?usage: $0 N SCENE.json PARTS_DIR OUT.png [render flags...]}
scene=${2:?usage: $0 N SCENE.json PARTS_DIR OUT.png [render flags...]}
dir=${3:?usage: $0 N SCENE.json PARTS_DIR OUT.png [render flags...]}
out=${4:?usage: $0 N SCENE.json PARTS_DIR OUT.png [render flags...]}
shift 4
case $n in '' | *[!0-9]* | 0) echo "$0: N must be a whole number >= 1, not '$n'" >&2; exit 2 ;; esac
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_ARGS:-} --array=0-$((n - 1)) "$here/render-array.sbatch" "$scene" "$dir" "$@")
array=${array%%;*}
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_ARGS:-} --dependency=afterok:"$array" "$here/merge.sbatch" "$dir" "$out")
merge=${merge%%;*}
echo "$array $merge"
