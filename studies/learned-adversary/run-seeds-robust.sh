#!/bin/sh
# Training seeds 1 and 2 of the fitted start on models/dqn-robust (seed 0: run-amortized.sh), so that its two
# cells report the median of three training seeds; each evaluated on 100 episodes, seeds 100000-100099.
# Usage: sh studies/learned-adversary/run-seeds-robust.sh EPS   (0.05 or 0.02)
set -e
cd "$(dirname "$0")/../.."
. .venv/bin/activate
e=$1
A=results/learned-adversary
C=$A/cells
for s in 1 2; do
  out=$A/amortized-dqn-robust-eps$e-seed$s
  [ -f $out/model.zip ] || zodrive attack-train models/dqn-robust --eps $e --steps 0 --pretrain-rounds 4 \
     --pretrain-episodes 10 --reward horizon --seed $s --out $out --no-progress > $out.txt 2>&1
  zodrive evaluate models/dqn-robust --attack learned:$out --eps $e --episodes 100 --workers 1 \
     --no-progress --out $C/dqn-robust-amortized-eps$e-seed$s-100 > $C/dqn-robust-amortized-eps$e-seed$s-100.txt 2>&1
done
