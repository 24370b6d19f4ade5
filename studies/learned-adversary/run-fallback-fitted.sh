#!/bin/sh
# The fitted start with the fallback target FASTER,not:SLOWER (FASTER, else at least not SLOWER), training seeds
# 0, 1, 2, each evaluated on 100 episodes, seeds 100000-100099 (results/learned-adversary/README.md, section "A fallback target").
# Usage: sh studies/learned-adversary/run-fallback-fitted.sh VICTIM EPS   (VICTIM: a folder under models/). A finished adversary is kept.
set -e
cd "$(dirname "$0")/../.."
Z="python -m zodrive"
A=results/learned-adversary
V=$1; E=$2
for S in 0 1 2; do
  tag=$( [ $S = 0 ] || echo "-seed$S" )
  name=amortized-fallback-$V-eps$E$tag
  cell=$V-amortized-fallback-eps$E$tag-100
  [ -f $A/$name/model.zip ] || $Z attack-train models/$V --eps $E --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 \
    --reward horizon --target FASTER,not:SLOWER --seed $S --out $A/$name --no-progress > $A/$name.txt 2>&1
  $Z evaluate models/$V --attack learned:$A/$name --eps $E --episodes 100 --seed 100000 --workers 1 --no-progress \
    --out $A/cells/$cell > $A/cells/$cell.txt 2>&1
done
