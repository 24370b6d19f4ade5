#!/bin/bash
# Vertex hold with a picker (`zodrive picker-train`, then `--attack vertex-hold:DIR`, 1 query per step):
# fit with seed SEED against MODEL at EPS into results/vertex-hold/picker/NAME-seedSEED, then evaluate it on
# 100 episodes, seeds 100000-100099, into results/vertex-hold/picker/cells/NAME-seedSEED. Each command's printed output is in the .txt beside the cell.
# Usage: bash studies/vertex-hold/picker/run.sh NAME MODEL EPS SEED [PICKER-TRAIN OPTIONS]
#   dqn-close models/dqn-close 0.02 0                                 (seeds 0, 1, 2)
#   dqn-driver models/dqn-driver 0.02 0 --probes 128 --switch 0       (450-step episodes; see results/vertex-hold/picker/README.md)
set -u
cd "$(dirname "$0")/../../.."
. .venv/bin/activate
name=$1; model=$2; eps=$3; seed=$4; shift 4
P=results/vertex-hold/picker
out=$P/$name-eps$eps-seed$seed
if [ ! -f $out/picker.pt ]; then
  echo "\$ zodrive picker-train $model --eps $eps --seed $seed --out $out $*" > $out.txt
  zodrive picker-train $model --eps $eps --seed $seed --out $out "$@" >> $out.txt 2>&1 || exit 1
fi
mkdir -p $P/cells
cell=$P/cells/$name-eps$eps-seed$seed
echo "\$ zodrive evaluate $model --attack vertex-hold:$out --eps $eps --episodes 100 --seed 100000 --out $cell" > $cell.txt
zodrive evaluate $model --attack vertex-hold:$out --eps $eps --episodes 100 --seed 100000 --workers 1 --out $cell \
  --no-progress >> $cell.txt 2>&1
