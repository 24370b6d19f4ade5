#!/bin/bash
# Vertex hold is random (its vertices): the cells where it matters, again with attack seeds 1 and 2
# (run.sh used 0), 100 episodes on seeds 100000-100099, into results/vertex-hold/cells/NAME-seedS. Two lanes; resumable.
# The DQN driver at eps 0.02 was added for the pickers' comparison (results/vertex-hold/picker/README.md).
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/vertex-hold/cells
cell() {  # NAME MODEL ARGS...
  name=$1; model=$2; shift 2
  echo "\$ zodrive evaluate $model --attack vertex-hold $* --episodes 100 --seed 100000 --out $C/$name" > $C/$name.txt
  zodrive evaluate $model --attack vertex-hold "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name \
    --no-progress >> $C/$name.txt 2>&1
}
lane() {
  s=$1
  cell dqn-close-eps0.02-seed$s models/dqn-close --eps 0.02 --attack-seed $s
  cell dqn-close-eps0.05-seed$s models/dqn-close --eps 0.05 --attack-seed $s
  cell dqn-driver-eps0.2-seed$s models/dqn-driver --eps 0.2 --attack-seed $s
  cell dqn-driver-eps0.02-seed$s models/dqn-driver --eps 0.02 --attack-seed $s
}
lane 1 & lane 2; wait
