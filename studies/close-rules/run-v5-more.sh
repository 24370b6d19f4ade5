#!/bin/bash
# models/dqn-close behind the shield v5: PGD through shield@0.02, and close-shield@0.02 under random
# search (8 % collisions under v4), 100 episodes per cell on seeds 100000-100099. One process; resumable.
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/close-rules/attacked
cell() {  # NAME ARGS...: one evaluation, its command and summary in NAME.txt
  name=$1; shift
  echo "\$ zodrive evaluate models/dqn-close $* --episodes 100 --seed 100000 --workers 1 --out $C/$name" > $C/$name.txt
  zodrive evaluate models/dqn-close "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name --no-progress \
    >> $C/$name.txt 2>&1
}
cell v5-close-shield@0.02-random-search-eps0.02 --defense close-shield@0.02 --attack random-search --eps 0.02
cell v5-shield@0.02-pgd-eps0.02 --defense shield@0.02 --attack pgd --eps 0.02
