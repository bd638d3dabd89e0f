#!/usr/bin/env bash
# Run one fireflies experiment as a Slurm job array: one shard per array task, then a merge
# job that starts only when every shard succeeded.
#
#   experiments/cluster/slurm-array.sh experiments/million.toml 32 /shared/fireflies/million
#
# Arguments: experiment file, number of shards, output directory on a filesystem every node
# sees. The `fireflies` binary must be on PATH on the compute nodes (cargo install --path .).
# Each task writes OUT/shards/shard-i-of-k.json atomically, so a task that dies leaves no
# partial file; resubmitting only the failed indices (sbatch --array=5,17 ...) is enough, and
# `fireflies merge` refuses to run while a shard is missing, duplicated or from another run.
set -euo pipefail

experiment=${1:?usage: slurm-array.sh EXPERIMENT.toml SHARDS OUT_DIR}
shards=${2:?number of shards}
out=${3:?output directory}
mkdir -p "$out/shards" "$out/logs"

array_job=$(sbatch --parsable \
    --job-name=fireflies-shard \
    --array="0-$((shards - 1))" \
    --cpus-per-task="${FIREFLIES_CPUS:-8}" \
    --time="${FIREFLIES_TIME:-02:00:00}" \
    --output="$out/logs/shard-%a.log" \
    --wrap="fireflies run '$experiment' --shard \${SLURM_ARRAY_TASK_ID}/$shards --threads \${SLURM_CPUS_PER_TASK} --out '$out/shards'")

sbatch --parsable \
    --job-name=fireflies-merge \
    --dependency="afterok:$array_job" \
    --cpus-per-task=1 \
    --time=00:30:00 \
    --output="$out/logs/merge.log" \
    --wrap="fireflies merge '$out/shards' --out '$out/report'"

echo "submitted array job $array_job ($shards shards) and its merge; report in $out/report"
