#!/bin/sh
# The learned adversary trained by PPO from the fitted start (attack-train --pretrain-rounds 4 --steps 50000)
# and its evaluations in results/learned-adversary/README.md, section "PPO from the fitted start".
# Usage (from the repository root): sh studies/learned-adversary/run-ppo.sh VICTIM EPS SEED EPISODES [TAG OPTION...]
#   VICTIM: a folder under models/; one job per core. TAG names a variant whose extra attack-train
#   options follow it, e.g. `sh studies/learned-adversary/run-ppo.sh dqn-robust 0.05 0 100 std0.2-w10k --explore-std 0.2 --critic-warmup 10000`.
set -e
Z="python -m zodrive"
A=results/learned-adversary
V=$1; E=$2; S=$3; N=$4
shift 4
T=""
if [ $# -gt 0 ]; then T="-$1"; shift; fi
name=ppo-$V-eps$E$T$( [ "$S" = 0 ] || echo "-seed$S" )
$Z attack-train models/$V --eps $E --steps 50000 --pretrain-rounds 4 --pretrain-episodes 10 --reward horizon \
   --seed $S "$@" --out $A/$name --no-progress > $A/$name.txt 2>&1
$Z evaluate models/$V --attack learned:$A/$name --eps $E --episodes $N --seed 100000 --workers 1 --no-progress \
   --out $A/cells/$name-$N > $A/cells/$name-$N.txt 2>&1
