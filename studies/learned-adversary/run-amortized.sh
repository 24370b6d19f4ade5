#!/bin/sh
# The amortized learned adversaries (attack-train --pretrain-rounds) and their evaluations in
# results/learned-adversary/README.md, section "A fitted start". One job at a time per core.
set -e
Z="python -m zodrive"
A=results/learned-adversary
C=$A/cells
for e in 0.05 0.02 0.2; do
  $Z attack-train models/dqn-driver --eps $e --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon \
     --out $A/amortized-dqn-driver-eps$e --no-progress > $A/amortized-dqn-driver-eps$e.txt 2>&1
  $Z evaluate models/dqn-driver --attack learned:$A/amortized-dqn-driver-eps$e --eps $e --episodes 30 --workers 1 \
     --no-progress --out $C/dqn-driver-amortized-eps$e > $C/dqn-driver-amortized-eps$e.txt 2>&1
done
# 100 episodes (seeds 100000-100099) at eps 0.05 and 0.2: the adversary, PGD and random search (patience 10,
# as the 30-episode cells above); the eps 0.05 cells start from the committed 30-episode ones and are extended
for e in 0.05 0.2; do
  for a in learned:$A/amortized-dqn-driver-eps$e pgd random-search; do
    name=$(echo $a | sed "s|learned:.*|amortized|")
    extra=$( [ "$name" = amortized ] || echo "--patience 10" )
    [ -d $C/dqn-driver-$name-eps$e ] && [ ! -d $C/dqn-driver-$name-eps$e-100 ] && cp -r $C/dqn-driver-$name-eps$e $C/dqn-driver-$name-eps$e-100
    $Z evaluate models/dqn-driver --attack $a --eps $e $extra --episodes 100 --workers 1 --no-progress \
       --out $C/dqn-driver-$name-eps$e-100 > $C/dqn-driver-$name-eps$e-100.txt 2>&1
  done
done
# the DDPG driver (target [1, 0.5], as every attack's default): the fitted adversaries at eps 0.2 and 0.05, 30 episodes;
# beside them PGD and random search at eps 0.05 (patience 10; at eps 0.2 the committed results/attacks-drivers cells)
for e in 0.2 0.05; do
  $Z attack-train models/ddpg-driver --eps $e --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon \
     --out $A/amortized-ddpg-driver-eps$e --no-progress > $A/amortized-ddpg-driver-eps$e.txt 2>&1
  $Z evaluate models/ddpg-driver --attack learned:$A/amortized-ddpg-driver-eps$e --eps $e --episodes 30 --workers 1 \
     --no-progress --out $C/ddpg-driver-amortized-eps$e > $C/ddpg-driver-amortized-eps$e.txt 2>&1
done
for a in pgd random-search; do
  $Z evaluate models/ddpg-driver --attack $a --eps 0.05 --patience 10 --episodes 30 --workers 1 --no-progress \
     --out $C/ddpg-driver-$a-eps0.05 > $C/ddpg-driver-$a-eps0.05.txt 2>&1
done
# a defended model: models/dqn-robust (robust distillation at eps 0.02), 100 episodes, beside its committed
# 100-episode cells in results/robustness-100 (PGD at eps 0.02, random search at eps 0.05)
for e in 0.02 0.05; do
  $Z attack-train models/dqn-robust --eps $e --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon \
     --out $A/amortized-dqn-robust-eps$e --no-progress > $A/amortized-dqn-robust-eps$e.txt 2>&1
  $Z evaluate models/dqn-robust --attack learned:$A/amortized-dqn-robust-eps$e --eps $e --episodes 100 --workers 1 \
     --no-progress --out $C/dqn-robust-amortized-eps$e-100 > $C/dqn-robust-amortized-eps$e-100.txt 2>&1
done
# two more defended models at eps 0.05 (SA-DQN and the paper's Algorithm 2), 30 episodes, beside PGD and random
# search with patience 10 on the same seeds
for m in dqn-sa dqn-at; do
  $Z attack-train models/$m --eps 0.05 --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon \
     --out $A/amortized-$m-eps0.05 --no-progress > $A/amortized-$m-eps0.05.txt 2>&1
  $Z evaluate models/$m --attack learned:$A/amortized-$m-eps0.05 --eps 0.05 --episodes 30 --workers 1 \
     --no-progress --out $C/$m-amortized-eps0.05 > $C/$m-amortized-eps0.05.txt 2>&1
  for a in pgd random-search; do
    $Z evaluate models/$m --attack $a --eps 0.05 --patience 10 --episodes 30 --workers 1 --no-progress \
       --out $C/$m-$a-eps0.05 > $C/$m-$a-eps0.05.txt 2>&1
  done
done
# the DDPG driver with 30 episodes per round (chosen on tuning seeds 900000-900029: 25.22 against 43.56 with 10 at eps 0.05)
for e in 0.2 0.05; do
  $Z attack-train models/ddpg-driver --eps $e --steps 0 --pretrain-rounds 4 --pretrain-episodes 30 --reward horizon \
     --out $A/amortized-ddpg-driver-e30-eps$e --no-progress > $A/amortized-ddpg-driver-e30-eps$e.txt 2>&1
  $Z evaluate models/ddpg-driver --attack learned:$A/amortized-ddpg-driver-e30-eps$e --eps $e --episodes 30 --workers 1 \
     --no-progress --out $C/ddpg-driver-amortized-e30-eps$e > $C/ddpg-driver-amortized-e30-eps$e.txt 2>&1
done
# the defended DDPG (models/ddpg-robust) at eps 0.05, 30 episodes, beside PGD and random search (patience 10)
$Z attack-train models/ddpg-robust --eps 0.05 --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon \
   --out $A/amortized-ddpg-robust-eps0.05 --no-progress > $A/amortized-ddpg-robust-eps0.05.txt 2>&1
$Z evaluate models/ddpg-robust --attack learned:$A/amortized-ddpg-robust-eps0.05 --eps 0.05 --episodes 30 --workers 1 \
   --no-progress --out $C/ddpg-robust-amortized-eps0.05 > $C/ddpg-robust-amortized-eps0.05.txt 2>&1
for a in pgd random-search; do
  $Z evaluate models/ddpg-robust --attack $a --eps 0.05 --patience 10 --episodes 30 --workers 1 --no-progress \
     --out $C/ddpg-robust-$a-eps0.05 > $C/ddpg-robust-$a-eps0.05.txt 2>&1
done
# training seeds 1 and 2 beside seed 0 (above) for the DQN driver at eps 0.05 and 0.2, 100 episodes each
for e in 0.05 0.2; do for s in 1 2; do
  $Z attack-train models/dqn-driver --eps $e --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon --seed $s \
     --out $A/amortized-dqn-driver-eps$e-seed$s --no-progress > $A/amortized-dqn-driver-eps$e-seed$s.txt 2>&1
  $Z evaluate models/dqn-driver --attack learned:$A/amortized-dqn-driver-eps$e-seed$s --eps $e --episodes 100 --workers 1 \
     --no-progress --out $C/dqn-driver-amortized-eps$e-seed$s-100 > $C/dqn-driver-amortized-eps$e-seed$s-100.txt 2>&1
done; done
