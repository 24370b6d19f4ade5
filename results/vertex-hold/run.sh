#!/bin/bash
# Vertex hold (`--attack vertex-hold`, 1 query per step) on every victim of the learned adversary's
# table (results/learned-adversary) and behind the shield, 100 episodes on seeds 100000-100099 per
# cell, into results/vertex-hold/cells/. Two lanes in parallel (long episodes / short ones); resumable.
# Usage: bash results/vertex-hold/run.sh; then python results/vertex-hold/paired.py > results/vertex-hold/paired.txt
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/vertex-hold/cells
cell() {  # NAME MODEL ARGS...: one evaluation, its command and summary in NAME.txt
  name=$1; model=$2; shift 2
  echo "\$ zodrive evaluate $model --attack vertex-hold $* --episodes 100 --seed 100000 --out $C/$name" > $C/$name.txt
  zodrive evaluate $model --attack vertex-hold "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name \
    --no-progress >> $C/$name.txt 2>&1
}
long() {
  cell dqn-driver-eps0.02 models/dqn-driver --eps 0.02
  cell dqn-robust-eps0.02 models/dqn-robust --eps 0.02
  cell dqn-driver+shield@0.02-eps0.02 models/dqn-driver --defense shield@0.02 --eps 0.02
  cell dqn-close+shield@0.02-eps0.02 models/dqn-close --defense shield@0.02 --eps 0.02
}
short() {
  cell dqn-close-eps0.02 models/dqn-close --eps 0.02
  cell dqn-close-eps0.05 models/dqn-close --eps 0.05
  cell dqn-robust-eps0.05 models/dqn-robust --eps 0.05
  cell dqn-driver-eps0.05 models/dqn-driver --eps 0.05
  cell dqn-driver-eps0.2 models/dqn-driver --eps 0.2
  cell ddpg-driver-eps0.2 models/ddpg-driver --eps 0.2
  cell ddpg-driver-eps0.05 models/ddpg-driver --eps 0.05
  cell ddpg-robust-eps0.05 models/ddpg-robust --eps 0.05
  cell td3-finetuned-eps0.2 models/td3-finetuned --eps 0.2
  cell dqn-driver+shield@0.05-eps0.05 models/dqn-driver --defense shield@0.05 --eps 0.05
}
long & short; wait
