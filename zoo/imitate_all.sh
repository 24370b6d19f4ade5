#!/usr/bin/env bash
# The zoo's policies for roundabout and intersection, where DQN from scratch (zoo/train.py, 20,000 steps) does
# not beat the constant actions: behaviour cloning with DAgger of the privileged look-ahead planner
# (baseline:planner reads the simulator), through zodrive's own `robust-train --method distill --kappa 0`
# (plain cloning: no robustness term). The student is an MLP of the zoo DQN's architecture, started from
# the seed-0 DQN of its scenario; 400 planner-labelled states, then 4 DAgger rounds of 400 states the
# student drives into. Finished runs are skipped, so it resumes.
# Run: OMP_NUM_THREADS=1 nohup nice -n 10 bash zoo/imitate_all.sh > zoo/imitate.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."
for seed in ${SEEDS:-0 1 2}; do
  for scenario in ${SCENARIOS:-intersection roundabout}; do
    out="models/zoo/$scenario-imitation/seed-$seed"
    [ -f "$out/model.zip" ] && { echo "$out/model.zip exists: skipped"; continue; }
    zodrive robust-train "models/zoo/$scenario-dqn/seed-0" --method distill --kappa 0 --teacher baseline:planner \
      --dagger 4 --steps 400 --epochs 50 --preset "$scenario" --seed "$seed" --out "$out" --no-progress
  done
done
