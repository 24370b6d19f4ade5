#!/bin/sh
# The evaluations of results/learned-adversary/README.md, one at a time (2 shared cores).
# The random-search and PGD cells start from the committed 10-episode cells of
# results/robustness-curve/cells (same settings: patience 10, seeds 100000+) and add episodes 10-29.
set -e
Z="python -m zodrive"
C=results/learned-adversary/cells
for e in 0.05 0.02; do
  $Z evaluate models/dqn-driver --attack learned:results/learned-adversary/adv-dqn-driver-eps$e-horizon --eps $e \
     --episodes 30 --no-progress --out $C/dqn-driver-learned-eps$e > $C/dqn-driver-learned-eps$e.txt 2>&1
done
for e in 0.05 0.02; do
  $Z evaluate models/dqn-driver --attack uniform-noise --eps $e --episodes 30 --no-progress \
     --out $C/dqn-driver-uniform-noise-eps$e > $C/dqn-driver-uniform-noise-eps$e.txt 2>&1
done
for b in faster slower; do
  $Z evaluate baseline:$b --episodes 30 --no-progress --out $C/baseline-$b-none > $C/baseline-$b-none.txt 2>&1
done
for a in pgd random-search; do for e in 0.05 0.02; do
  $Z evaluate models/dqn-driver --attack $a --eps $e --patience 10 --episodes 30 --no-progress \
     --out $C/dqn-driver-$a-eps$e > $C/dqn-driver-$a-eps$e.txt 2>&1
done; done
# against the shielded driver (the adversary trained with --defense shield@0.02, 50 000 steps)
$Z evaluate models/dqn-driver --defense shield@0.02 --attack learned:results/learned-adversary/adv-dqn-driver+shield@0.02-eps0.02-horizon \
   --eps 0.02 --episodes 30 --no-progress --out "$C/dqn-driver+shield@0.02-learned-eps0.02" > "$C/dqn-driver+shield@0.02-learned-eps0.02.txt" 2>&1
$Z evaluate models/dqn-driver --defense shield@0.02 --episodes 30 --no-progress --out "$C/dqn-driver+shield@0.02-none" > "$C/dqn-driver+shield@0.02-none.txt" 2>&1
# 100 episodes (seeds 100000-100099) against the shield: the 30-episode cells above, extended
cp -r "$C/dqn-driver+shield@0.02-learned-eps0.02" "$C/dqn-driver+shield@0.02-learned-eps0.02-100"
$Z evaluate models/dqn-driver --defense shield@0.02 --attack learned:results/learned-adversary/adv-dqn-driver+shield@0.02-eps0.02-horizon \
   --eps 0.02 --episodes 100 --no-progress --out "$C/dqn-driver+shield@0.02-learned-eps0.02-100" > "$C/dqn-driver+shield@0.02-learned-eps0.02-100.txt" 2>&1
cp -r "$C/dqn-driver+shield@0.02-none" "$C/dqn-driver+shield@0.02-none-100"
$Z evaluate models/dqn-driver --defense shield@0.02 --episodes 100 --no-progress --out "$C/dqn-driver+shield@0.02-none-100" > "$C/dqn-driver+shield@0.02-none-100.txt" 2>&1
