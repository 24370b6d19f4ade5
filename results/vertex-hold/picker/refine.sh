#!/bin/bash
# Refine committed pickers for vertex check (`zodrive picker-train --refine DIR`, default settings: 480 episodes under
# vertex check, 512 vertices queried where a check failed, one epoch), then evaluate each refined picker with
# check.sh on 100 episodes, seeds 100000-100099 (cells/check-NAME-refined). Printed output in the .txt beside each.
# Usage: bash results/vertex-hold/picker/refine.sh MODEL EPS NAME...
#   models/dqn-close 0.02 dqn-close-eps0.02-seed0 dqn-close-eps0.02-seed1 dqn-close-eps0.02-seed2
set -u
cd "$(dirname "$0")/../../.."
. .venv/bin/activate
model=$1; eps=$2; shift 2
P=results/vertex-hold/picker
for name in "$@"; do
  out=$P/$name-refined
  if [ ! -f $out/fallback.pt ]; then
    echo "\$ zodrive picker-train $model --eps $eps --refine $P/$name --out $out" > $out.txt
    zodrive picker-train $model --eps $eps --refine $P/$name --out $out >> $out.txt 2>&1 || exit 1
  fi
  bash $P/check.sh $model $eps check "" $name-refined || exit 1
done
