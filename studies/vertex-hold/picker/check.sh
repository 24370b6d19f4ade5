#!/bin/bash
# Vertex check (`--attack vertex-check:DIR`) with the pickers run.sh fitted: the same picker folders, evaluated on
# 100 episodes, seeds 100000-100099, into results/vertex-hold/picker/cells/PREFIX-NAME. Each command's printed output is in the .txt beside the cell.
# Usage: bash studies/vertex-hold/picker/check.sh MODEL EPS PREFIX "OPTIONS" NAME...
#   models/dqn-close 0.02 check "" dqn-close-eps0.02-seed0 ...                          (1 query per step)
#   models/dqn-close 0.02 check-below0.998 "--check-below 0.998" dqn-close-eps0.02-seed0 ...  (<= 1 on average)
set -u
cd "$(dirname "$0")/../../.."
. .venv/bin/activate
model=$1; eps=$2; prefix=$3; options=$4; shift 4
P=results/vertex-hold/picker
mkdir -p $P/cells
for name in "$@"; do
  cell=$P/cells/$prefix-$name
  [ -f $cell/summary.json ] && continue
  echo "\$ zodrive evaluate $model --attack vertex-check:$P/$name $options --eps $eps --episodes 100 --seed 100000 --out $cell" > $cell.txt
  zodrive evaluate $model --attack vertex-check:$P/$name $options --eps $eps --episodes 100 --seed 100000 --workers 1 \
    --out $cell --no-progress >> $cell.txt 2>&1 || exit 1
done
