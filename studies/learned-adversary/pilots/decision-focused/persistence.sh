#!/bin/bash
# vertex_persistence.py on three cases, 5 episodes each (tuning seeds 900000-900004), into
# results/learned-adversary/pilots/decision-focused/persistence.txt
set -u
cd "$(dirname "$0")/../../../.."
. .venv/bin/activate
S=studies/learned-adversary/pilots/decision-focused
P=results/learned-adversary/pilots/decision-focused
for args in "models/dqn-close 0.02" "models/dqn-close 0.02 --under results/learned-adversary/amortized-dqn-close-eps0.02" \
            "models/dqn-driver 0.02" "models/dqn-driver 0.02 --under results/learned-adversary/amortized-dqn-driver-eps0.02"; do
  echo "\$ python $S/vertex_persistence.py $args --episodes 5"
  python $S/vertex_persistence.py $args --episodes 5 2>&1 | grep -v "^WARN"
done > $P/persistence.txt
