#!/bin/bash
# Submits a sandstep experiment or sweep to Slurm as a job array of shards and a merge that
# runs when they are over (docs/cluster.md):
#
#   docs/cluster/submit.sh experiment config/experiments/leg_curvature.yaml out/leg_curvature
#
# Optional environment: SANDSTEP_ARGS (options for every job, e.g. "--set cycles=2" for an
# experiment), SANDSTEP (the binary), SANDSTEP_MAX_TASKS (most array tasks, default 64: a
# task then runs several runs one after another), SBATCH_ARGS (more sbatch options for both
# submissions, e.g. "--partition=cpu").
set -euo pipefail

if [ $# -ne 3 ] || { [ "$1" != experiment ] && [ "$1" != sweep ]; }; then
    echo "usage: $0 experiment|sweep FILE OUT_FOLDER" >&2
    exit 2
fi
export SANDSTEP_COMMAND=$1 SANDSTEP_FILE=$2 SANDSTEP_OUT=$3
export SANDSTEP=${SANDSTEP:-sandstep}
here=$(cd "$(dirname "$0")" && pwd)

# shellcheck disable=SC2086 # SANDSTEP_ARGS and SBATCH_ARGS are split at spaces on purpose.
runs=$("$SANDSTEP" "$SANDSTEP_COMMAND" "$SANDSTEP_FILE" --list ${SANDSTEP_ARGS:-} | wc -l)
max_tasks=${SANDSTEP_MAX_TASKS:-64}
if [ "$runs" -lt 1 ] || [ "$max_tasks" -lt 1 ]; then
    echo "$0: $runs runs and SANDSTEP_MAX_TASKS=$max_tasks: nothing to submit" >&2
    exit 1
fi
tasks=$((runs < max_tasks ? runs : max_tasks))
export SANDSTEP_SHARDS=$tasks
mkdir -p "$SANDSTEP_OUT"
# shellcheck disable=SC2086
array=$(sbatch --parsable --export=ALL --array="1-$tasks" ${SBATCH_ARGS:-} \
    "$here/study.sbatch")
array=${array%%;*}
# shellcheck disable=SC2086
merge=$(sbatch --parsable --export=ALL --dependency="afterany:$array" ${SBATCH_ARGS:-} \
    "$here/merge.sbatch")
echo "$runs runs in $tasks array tasks: job $array; merge: job ${merge%%;*}"
echo "results: $SANDSTEP_OUT/results.csv once job ${merge%%;*} is over"
