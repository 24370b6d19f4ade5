#!/bin/bash
# shield@0.05 under PGD at eps 0.05 and the constant brake (always SLOWER) on 300 episodes
# (seeds 100000-100299): is the shield's 3 % against the brake's 2 % on 100 episodes a difference?
# Paired by seed with studies/shield/paired_crashes.py. One process; resumable.
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/shield/cells-v5
ev() {
  name=$1; shift
  echo "\$ zodrive evaluate $* --episodes 300 --seed 100000 --workers 1 --out $C/$name" > $C/$name.txt
  zodrive evaluate "$@" --episodes 300 --seed 100000 --workers 1 --out $C/$name --no-progress >> $C/$name.txt 2>&1
}
ev baseline-slower-300 baseline:slower
ev dqn-driver+shield@0.05-pgd-eps0.05-300 models/dqn-driver --defense shield@0.05 --attack pgd --eps 0.05
