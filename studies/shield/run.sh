#!/bin/bash
# The shield's measurements, one process at a time (the machine is shared): 30 episodes per cell,
# seeds 100000-100029. Each line is an ordinary resumable `zodrive evaluate`.
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
N=30
ev() {  # ev NAME ARGS...: evaluate into results/shield/cells/NAME, printed output kept in NAME.txt
  name=$1; shift
  echo "\$ zodrive evaluate $* --episodes $N --seed 100000 --workers 1 --out results/shield/cells/$name" > results/shield/cells/$name.txt
  zodrive evaluate "$@" --episodes $N --seed 100000 --workers 1 --out results/shield/cells/$name --no-progress >> results/shield/cells/$name.txt 2>&1
}
ev dqn-driver+shield@0.02-none models/dqn-driver --defense shield@0.02
ev dqn-driver+shield@0.05-none models/dqn-driver --defense shield@0.05
ev dqn-driver-none models/dqn-driver
ev dqn-driver+shield@0.02-random-search-eps0.02 models/dqn-driver --defense shield@0.02 --attack random-search --eps 0.02
ev dqn-driver+shield@0.05-random-search-eps0.05 models/dqn-driver --defense shield@0.05 --attack random-search --eps 0.05
ev dqn-driver+shield@0.02-random-search-eps0.05 models/dqn-driver --defense shield@0.02 --attack random-search --eps 0.05
ev dqn-driver+shield@0.05-zo-signsgd-eps0.05 models/dqn-driver --defense shield@0.05 --attack zo-signsgd --eps 0.05
ev dqn-driver+shield@0.02-zo-signsgd-eps0.02 models/dqn-driver --defense shield@0.02 --attack zo-signsgd --eps 0.02
echo done > results/shield/cells/QUEUE_DONE
