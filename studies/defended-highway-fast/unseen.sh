#!/usr/bin/env bash
# Shield v6 was found on evaluation seeds (100072, 100095): recheck it on 100 seeds no run had seen
# (200000-200099), against the brake and against v5 under the attack that found v5's crashes.
#   bash studies/defended-highway-fast/unseen.sh [V5_SRC]     # V5_SRC: src/ of 885db76 (shield v5)
set -euo pipefail
OUT=studies/defended-highway-fast/unseen
M=models/zoo/highway-fast-dqn/seed-0
COMMON=(--preset highway-fast --episodes 100 --seed 200000 --no-progress)
ATTACK=(--eps 0.05 --query-budget 500)
zodrive evaluate baseline:slower "${COMMON[@]}" --out $OUT/brake
zodrive evaluate $M --defense shield@0.05 --trust-model "${COMMON[@]}" --out $OUT/v6-none
zodrive evaluate $M --defense shield@0.05 --trust-model "${COMMON[@]}" --attack random-search "${ATTACK[@]}" --out $OUT/v6-random-search
zodrive evaluate $M --defense shield@0.05 --trust-model "${COMMON[@]}" --attack zo-signsgd "${ATTACK[@]}" --out $OUT/v6-zo-signsgd
if [ -n "${1:-}" ]; then
  PYTHONPATH=$1 zodrive evaluate $M --defense shield@0.05 --trust-model "${COMMON[@]}" --attack random-search "${ATTACK[@]}" --out $OUT/v5-random-search
fi
