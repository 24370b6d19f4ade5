#!/bin/sh
# Random search's attack seeds 1 and 2 on models/dqn-robust at eps 0.05 (seed 0: results/robustness-100), so that
# the per-step side of that cell is a median over three seeds too; 100 episodes, seeds 100000-100099.
set -e
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/learned-adversary/cells
for s in 1 2; do
  cell=$C/dqn-robust-random-search-eps0.05-seed$s-100
  cmd="zodrive evaluate models/dqn-robust --attack random-search --eps 0.05 --patience 10 --attack-seed $s --episodes 100 --workers 1 --no-progress --out $cell"
  { echo "\$ $cmd"; $cmd 2>&1; } > $cell.txt
done
