#!/bin/sh
# DAgger students of baseline:close-rules (the shipped dqn-imitation recipe: ROUNDS rounds of 10,000 states,
# 100 epochs, from the paper DQN's network), their 100 tuning episodes (seeds 900000-900099: how the
# number of rounds was chosen) and their 100 evaluation episodes (seeds 100000-100099).
# Usage: sh studies/close-rules/run-dagger.sh SEED [ROUNDS]   (SEED: 20000, 21000 or 22000; ROUNDS: 6 (default)
# or 10; one job per core)
set -e
S=$1
R=${2:-6}
Z="python -m zodrive"
[ -f runs/close/dagger$R-s$S/model.zip ] || \
$Z robust-train models/dqn --method distill --teacher baseline:close-rules --dagger $R --steps 10000 --epochs 100 \
   --kappa 0 --seed $S --out runs/close/dagger$R-s$S --no-progress > results/close-rules/dagger$R-s$S.txt 2>&1
$Z evaluate runs/close/dagger$R-s$S/model.zip --episodes 100 --seed 900000 --workers 1 --no-progress \
   --out results/close-rules/tune-dagger$R-s$S > results/close-rules/tune-dagger$R-s$S.txt 2>&1
$Z evaluate runs/close/dagger$R-s$S/model.zip --episodes 100 --seed 100000 --workers 1 --no-progress \
   --out results/close-rules/eval-dagger$R-s$S > results/close-rules/eval-dagger$R-s$S.txt 2>&1
