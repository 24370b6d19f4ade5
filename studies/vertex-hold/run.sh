#!/bin/bash
# Vertex hold (`--attack vertex-hold`, 1 query per step) on every victim of the learned adversary's
# table (results/learned-adversary) and behind the shield, 100 episodes on seeds 100000-100099 per
# cell, into results/vertex-hold/cells/. Two lanes in parallel (long episodes / short ones); resumable.
# Usage: bash studies/vertex-hold/run.sh; then python studies/vertex-hold/paired.py > results/vertex-hold/paired.txt
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/vertex-hold/cells
. studies/vertex-hold/cell.sh
hold() { cell vertex-hold "$@"; }  # NAME MODEL ARGS...
long() {
  hold dqn-driver-eps0.02 models/dqn-driver --eps 0.02
  hold dqn-robust-eps0.02 models/dqn-robust --eps 0.02
  hold dqn-driver+shield@0.02-eps0.02 models/dqn-driver --defense shield@0.02 --eps 0.02
  hold dqn-close+shield@0.02-eps0.02 models/dqn-close --defense shield@0.02 --eps 0.02
}
short() {
  hold dqn-close-eps0.02 models/dqn-close --eps 0.02
  hold dqn-close-eps0.05 models/dqn-close --eps 0.05
  hold dqn-robust-eps0.05 models/dqn-robust --eps 0.05
  hold dqn-driver-eps0.05 models/dqn-driver --eps 0.05
  hold dqn-driver-eps0.2 models/dqn-driver --eps 0.2
  hold ddpg-driver-eps0.2 models/ddpg-driver --eps 0.2
  hold ddpg-driver-eps0.05 models/ddpg-driver --eps 0.05
  hold ddpg-robust-eps0.05 models/ddpg-robust --eps 0.05
  hold td3-finetuned-eps0.2 models/td3-finetuned --eps 0.2
  hold dqn-driver+shield@0.05-eps0.05 models/dqn-driver --defense shield@0.05 --eps 0.05
}
long & short; wait
