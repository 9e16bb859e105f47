#!/bin/bash
# Statistical validation as a Slurm job array: one shard per array task, then one merge job.
#   sbatch --array=0-15 scripts/slurm_validate.sh            # 16 shards
#   sbatch --dependency=afterok:<array job id> --wrap \
#     "rfmlab validate validations/validate.toml --merge --out results/validate"
# Unit k runs in shard k mod n, with its own seed: the merged tables do not depend on n.
#SBATCH --job-name=rfmlab-validate
#SBATCH --cpus-per-task=2
#SBATCH --time=02:00:00
#SBATCH --output=validate-%A_%a.log
set -euo pipefail
FILE=${FILE:-validations/validate.toml}
OUT=${OUT:-results/validate}
N=${SLURM_ARRAY_TASK_COUNT:?run as an array job: sbatch --array=0-<n-1>}
I=${SLURM_ARRAY_TASK_ID:?}
export RAYON_NUM_THREADS=${SLURM_CPUS_PER_TASK:-2}
rfmlab --quiet validate "$FILE" --shard "$I/$N" --out "$OUT"
