#!/usr/bin/env bash
# Train the whole zoo, one run after another on one core (finished runs are skipped, so it resumes).
# Run: OMP_NUM_THREADS=1 nohup nice -n 19 bash zoo/train_all.sh > zoo/train.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."
for seed in 0 1 2; do
  for scenario in highway-fast merge roundabout intersection; do
    python zoo/train.py --scenario "$scenario" --seed "$seed" --out "models/zoo/$scenario-dqn/seed-$seed"
  done
done
