#!/bin/bash
# Vertex check (1 query per step: the check comes before the feed) with the DQN driver's pickers (picker/check.sh).
# The blind cells results/vertex-hold/cells/check-* (`--attack vertex-check` without a picker, on the cells where
# vertex hold matters, 100 episodes on seeds 100000-100099) were made before blind vertex check was removed
# (docs/attacks.md, "Removed options"); run them from a checkout of that time. The dqn-close pickers: bash studies/vertex-hold/picker/check.sh
# models/dqn-close 0.02 check "" dqn-close-eps0.02-seed{0,1,2} dqn-close-rank-eps0.02-seed{0,1,2} (and with
# check-below0.998 "--check-below 0.998" for the same names).
# Usage: bash studies/vertex-hold/run-check.sh; then python studies/vertex-hold/paired.py > results/vertex-hold/paired.txt
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
bash studies/vertex-hold/picker/check.sh models/dqn-driver 0.02 check "" dqn-driver-eps0.02-seed0 dqn-driver-eps0.02-seed1 \
  dqn-driver-eps0.02-seed2
