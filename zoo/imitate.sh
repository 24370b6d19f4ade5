#!/usr/bin/env bash
# The zoo's highway-fast family: behaviour cloning of baseline:rules (it reads the same observation)
# with DAgger, through zodrive's own `robust-train --method distill --kappa 0` (plain cloning, no
# robustness term). The student is an MLP of the zoo DQN's architecture, started from the zoo DQN of
# the same seed; 10,000 states the rules drive, then 4 rounds of 10,000 states the student drives,
# every state labelled by the rules; 50 epochs per refit. About 18 minutes per seed on one core.
# Why this family: studies/zoo-recipe/README.md ("Cloning the rules with DAgger").
# Finished runs are skipped, so it resumes.
# Run: OMP_NUM_THREADS=1 nohup nice -n 10 bash zoo/imitate.sh > zoo/imitate.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."
for seed in ${SEEDS:-0 1 2}; do
  out="models/zoo/highway-fast-imitation/seed-$seed"
  [ -f "$out/model.zip" ] && { echo "$out/model.zip exists: skipped"; continue; }
  zodrive robust-train "models/zoo/highway-fast-dqn/seed-$seed" --method distill --kappa 0 --teacher baseline:rules \
    --dagger 4 --steps 10000 --epochs 50 --preset highway-fast --seed "$seed" --out "$out" --no-progress
done
