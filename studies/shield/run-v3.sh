#!/bin/bash
# The shield v3 (superseded by v4, run-v4.sh; `zodrive.defense.shield.VERSION` 3: the lane beyond checked while the ego may be
# mid-change, and the escape from an own lane too close to stay in), 100 episodes per cell on
# seeds 100000-100099, into results/shield/cells-v3/ (removed: in git history, commit 323cf59); one process, one cell at a time. The learned adversary is
# retrained against v3 (one trained against v2 is refused: its version differs).
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/shield/cells-v3
A="results/learned-adversary/adv-dqn-driver+shield@0.02-v3-eps0.02-horizon"
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
