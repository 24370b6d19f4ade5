#!/usr/bin/env bash
# The zoo's imitation families: behaviour cloning with DAgger of an observation-reading rule driver,
# through zodrive's own `robust-train --method distill --kappa 0` (plain cloning, no robustness term).
# The student is an MLP of the zoo DQN's architecture, started from the zoo DQN of the same seed;
# 10,000 states the teacher drives, then 4 rounds of 10,000 states the student drives, every state
# labelled by the teacher; 50 epochs per refit. About 18 minutes per seed on one core.
#   highway-fast: baseline:rules, --seed N;
#   merge: baseline:brake-escape, --seed 100N (training seeds below 50,000, held-out agreement on 51000+N on,
#          clear of the tuning seeds validate.py uses).
# Why these families: studies/zoo-recipe/README.md ("Cloning the rules with DAgger", "Cloning a brake
# that escapes"). Finished runs are skipped, so it resumes.
# Run: OMP_NUM_THREADS=1 nohup nice -n 10 bash zoo/imitate.sh > zoo/imitate.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."
imitate() {  # scenario teacher seed dagger-seed
  local out="models/zoo/$1-imitation/seed-$3"
  [ -f "$out/model.zip" ] && { echo "$out/model.zip exists: skipped"; return; }
  zodrive robust-train "models/zoo/$1-dqn/seed-$3" --method distill --kappa 0 --teacher "baseline:$2" \
    --dagger 4 --steps 10000 --epochs 50 --preset "$1" --seed "$4" --out "$out" --no-progress
}
for seed in ${SEEDS:-0 1 2}; do
  imitate highway-fast rules "$seed" "$seed"
  imitate merge brake-escape "$seed" "100$seed"
done
