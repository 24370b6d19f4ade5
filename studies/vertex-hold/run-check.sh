#!/bin/bash
# Vertex check (`--attack vertex-check`, 1 query per step: the check comes before the feed) on the cells where
# vertex hold matters, 100 episodes on seeds 100000-100099, into results/vertex-hold/cells/check-*; and with
# the DQN driver's pickers (picker/check.sh). The dqn-close pickers: bash studies/vertex-hold/picker/check.sh
# models/dqn-close 0.02 check "" dqn-close-eps0.02-seed{0,1,2} dqn-close-rank-eps0.02-seed{0,1,2} (and with
# check-below0.998 "--check-below 0.998" for the same names).
# Usage: bash studies/vertex-hold/run-check.sh; then python studies/vertex-hold/paired.py > results/vertex-hold/paired.txt
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/vertex-hold/cells
. studies/vertex-hold/cell.sh
check() { name=$1; shift; cell vertex-check check-$name "$@"; }  # NAME MODEL ARGS...
blind() {
  check dqn-close-eps0.02 models/dqn-close --eps 0.02
  check dqn-close-eps0.05 models/dqn-close --eps 0.05
  check dqn-driver-eps0.2 models/dqn-driver --eps 0.2
}
picked() {
  bash studies/vertex-hold/picker/check.sh models/dqn-driver 0.02 check "" dqn-driver-eps0.02-seed0 dqn-driver-eps0.02-seed1 \
    dqn-driver-eps0.02-seed2
}
blind & picked; wait
