#!/bin/bash
# Vertex check (`--attack vertex-check:DIR`, 1 query per step) with the pickers run.sh fitted: the same
# picker folders, evaluated on 100 episodes, seeds 100000-100099, into cells/check-NAME. Each command's
# printed output is in the .txt beside. Usage: bash results/vertex-hold/picker/check.sh MODEL EPS NAME...
#   models/dqn-close 0.02 dqn-close-eps0.02-seed0 dqn-close-rank-eps0.02-seed0 ...
set -u
cd "$(dirname "$0")/../../.."
. .venv/bin/activate
model=$1; eps=$2; shift 2
P=results/vertex-hold/picker
mkdir -p $P/cells
for name in "$@"; do
  cell=$P/cells/check-$name
  echo "\$ zodrive evaluate $model --attack vertex-check:$P/$name --eps $eps --episodes 100 --seed 100000 --out $cell" > $cell.txt
  zodrive evaluate $model --attack vertex-check:$P/$name --eps $eps --episodes 100 --seed 100000 --workers 1 --out $cell \
    --no-progress >> $cell.txt 2>&1 || exit 1
done
