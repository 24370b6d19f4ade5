#!/bin/sh
# The continuous victims' learned-adversary cells and their random-search comparisons extended from 30 to
# 100 episodes (seeds 100000-100099): each 30-episode cell is copied to a "-100" folder and the resumable
# `zodrive evaluate` adds episodes 30-99 under the same key (model SHA-256, preset, attack, seeds).
# Usage: sh studies/learned-adversary/run-continuous-100.sh   (one job; about 10 minutes on one core)
set -e
Z="python -m zodrive"
C=results/learned-adversary/cells
extend() {  # SRC DST MODEL ATTACK-OPTIONS...
  src=$1; dst=$2; model=$3; shift 3
  [ -d $dst ] || cp -r $src $dst
  $Z evaluate $model "$@" --episodes 100 --seed 100000 --workers 1 --no-progress --out $dst > $dst.txt 2>&1
}
for s in "" -seed1 -seed2; do
  extend $C/ppo-ddpg-driver-eps0.2$s-30 $C/ppo-ddpg-driver-eps0.2$s-100 models/ddpg-driver \
    --attack learned:results/learned-adversary/ppo-ddpg-driver-eps0.2$s --eps 0.2
  extend $C/ppo-ddpg-driver-eps0.05$s-30 $C/ppo-ddpg-driver-eps0.05$s-100 models/ddpg-driver \
    --attack learned:results/learned-adversary/ppo-ddpg-driver-eps0.05$s --eps 0.05
done
extend $C/ppo-ddpg-robust-eps0.05-30 $C/ppo-ddpg-robust-eps0.05-100 models/ddpg-robust \
  --attack learned:results/learned-adversary/ppo-ddpg-robust-eps0.05 --eps 0.05
extend $C/ppo-td3-finetuned-eps0.2-30 $C/ppo-td3-finetuned-eps0.2-100 models/td3-finetuned \
  --attack learned:results/learned-adversary/ppo-td3-finetuned-eps0.2 --eps 0.2
extend $C/ddpg-driver-random-search-eps0.05 $C/ddpg-driver-random-search-eps0.05-100 models/ddpg-driver \
  --attack random-search --eps 0.05 --patience 10
extend $C/ddpg-robust-random-search-eps0.05 $C/ddpg-robust-random-search-eps0.05-100 models/ddpg-robust \
  --attack random-search --eps 0.05 --patience 10
extend results/attacks-drivers/cells/ddpg-driver-random-search-eps0.2 $C/ddpg-driver-random-search-eps0.2-100 \
  models/ddpg-driver --attack random-search --eps 0.2
extend results/attacks-td3-finetuned/cells/td3-finetuned-random-search-eps0.2 $C/td3-finetuned-random-search-eps0.2-100 \
  models/td3-finetuned --attack random-search --eps 0.2
