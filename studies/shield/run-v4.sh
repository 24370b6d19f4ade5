#!/bin/bash
# The shield v4 (`zodrive.defense.shield.VERSION`: v3's mid-change test and escape, the escape
# minding the lane beyond its target and a car centred in it), 100 episodes per cell on
# seeds 100000-100099, into results/shield/cells-v4/; one process, one cell at a time. The learned adversary is
# retrained against v4 (one trained against an earlier version is refused: its version differs).
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/shield/cells-v4
A="results/learned-adversary/adv-dqn-driver+shield@0.02-v4-eps0.02-horizon"
mkdir -p $C
ev() {
  name=$1; shift
  echo "\$ zodrive evaluate $* --episodes 100 --seed 100000 --workers 1 --out $C/$name" > $C/$name.txt
  zodrive evaluate "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name --no-progress >> $C/$name.txt 2>&1
}
[ -f "$A/model.zip" ] || zodrive attack-train models/dqn-driver --eps 0.02 --steps 50000 --reward horizon \
  --defense shield@0.02 --out "$A" --no-progress > "$C/attack-train.txt" 2>&1
ev dqn-driver+shield@0.02-learned-eps0.02 models/dqn-driver --defense shield@0.02 --attack "learned:$A" --eps 0.02
ev dqn-driver+shield@0.02-none models/dqn-driver --defense shield@0.02
ev dqn-driver+shield@0.02-pgd-eps0.02 models/dqn-driver --defense shield@0.02 --attack pgd --eps 0.02
ev dqn-driver+shield@0.05-none models/dqn-driver --defense shield@0.05
ev dqn-driver+shield@0.05-pgd-eps0.05 models/dqn-driver --defense shield@0.05 --attack pgd --eps 0.05
ev dqn-driver+shield@0.02-random-search-eps0.02 models/dqn-driver --defense shield@0.02 --attack random-search --eps 0.02
ev dqn-driver+shield@0.05-random-search-eps0.05 models/dqn-driver --defense shield@0.05 --attack random-search --eps 0.05
