#!/bin/bash
# The shield v4 under the learned adversary with a fitted start (attack-train --pretrain-rounds,
# results/learned-adversary/README.md "A fitted start"), trained against each shielded system;
# 100 episodes per cell on seeds 100000-100099, into results/shield/cells-v4/, as run-v4.sh.
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/shield/cells-v4
L=results/learned-adversary
for e in 0.02 0.05; do
  A="$L/amortized-dqn-driver+shield@$e-v4-eps$e"
  [ -f "$A/model.zip" ] || zodrive attack-train models/dqn-driver --defense shield@$e --eps $e --steps 0 --pretrain-rounds 4 \
    --pretrain-episodes 10 --reward horizon --out "$A" --no-progress > "$A.txt" 2>&1
  name=dqn-driver+shield@$e-fitted-eps$e
  echo "\$ zodrive evaluate models/dqn-driver --defense shield@$e --attack learned:$A --eps $e --episodes 100 --seed 100000 --workers 1 --out $C/$name" > $C/$name.txt
  zodrive evaluate models/dqn-driver --defense shield@$e --attack "learned:$A" --eps $e --episodes 100 --seed 100000 \
    --workers 1 --out $C/$name --no-progress >> $C/$name.txt 2>&1 &
done
wait
