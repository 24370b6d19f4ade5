#!/bin/bash
# models/dqn-close against the learned adversary with a fitted start (attack-train --pretrain-rounds,
# results/learned-adversary/README.md "A fitted start") at eps 0.02 and 0.05, bare, and behind the
# shield v5 at eps 0.02 (clean and under random search), 100 episodes per cell on seeds
# 100000-100099, into results/close-rules/attacked/ beside the v4 cells. One process; resumable.
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/close-rules/attacked
L=results/learned-adversary
cell() {  # NAME ARGS...: one evaluation, its command and summary in NAME.txt
  name=$1; shift
  echo "\$ zodrive evaluate models/dqn-close $* --episodes 100 --seed 100000 --workers 1 --out $C/$name" > $C/$name.txt
  zodrive evaluate models/dqn-close "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name --no-progress \
    >> $C/$name.txt 2>&1
}
for e in 0.05 0.02; do
  A=$L/amortized-dqn-close-eps$e
  [ -f "$A/model.zip" ] || zodrive attack-train models/dqn-close --eps $e --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 \
    --reward horizon --out $A --no-progress > $A.txt 2>&1
  cell amortized-eps$e --attack learned:$A --eps $e
done
cell v5-shield@0.02-none --defense shield@0.02
cell v5-shield@0.02-random-search-eps0.02 --defense shield@0.02 --attack random-search --eps 0.02
