#!/bin/bash
# The shield after the lane-existence fix (v2: a lane change only towards a lane that exists for
# every ego lateral position within eps), 30 episodes per cell, seeds 100000-100029, into results/shield/cells-v2/
# (the results key does not include the code version, so v1's folders must not be resumed).
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
N=30
mkdir -p results/shield/cells-v2
ev() {
  name=$1; shift
  echo "\$ zodrive evaluate $* --episodes $N --seed 100000 --workers 1 --out results/shield/cells-v2/$name" > results/shield/cells-v2/$name.txt
  zodrive evaluate "$@" --episodes $N --seed 100000 --workers 1 --out results/shield/cells-v2/$name --no-progress >> results/shield/cells-v2/$name.txt 2>&1
}
ev dqn-driver+shield@0.05-random-search-eps0.05 models/dqn-driver --defense shield@0.05 --attack random-search --eps 0.05
ev dqn-driver+shield@0.05-none models/dqn-driver --defense shield@0.05
ev dqn-driver+shield@0.02-random-search-eps0.02 models/dqn-driver --defense shield@0.02 --attack random-search --eps 0.02
ev dqn-driver+shield@0.02-none models/dqn-driver --defense shield@0.02
