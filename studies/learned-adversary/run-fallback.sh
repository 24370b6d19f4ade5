#!/bin/sh
# Per-step attacks with the fallback target FASTER,not:SLOWER (FASTER, else at least not SLOWER), 100 episodes on
# seeds 100000-100099 (results/learned-adversary/README.md, section "A fallback target"). The fitted start with that target:
# run-fallback-fitted.sh. Usage: sh studies/learned-adversary/run-fallback.sh rs|pgd|rs-driver [fallback]|rs-close
#   rs:  random search on models/dqn-robust at eps 0.05, attack seeds 0, 1, 2
#   rs-driver: random search on the DQN driver at eps 0.02 (~450 queries per step for ~400 steps an episode),
#        without the fallback, or with it given `fallback`
#   rs-close: random search with the fallback on models/dqn-close at eps 0.02 (no patience, as its committed cell)
#   pgd: white-box PGD where PGD was the strongest per-step attack (the DQN driver at eps 0.02 and 0.05,
#        dqn-robust at eps 0.02)
set -e
cd "$(dirname "$0")/../.."
Z="python -m zodrive"
A=results/learned-adversary
T=FASTER,not:SLOWER
if [ "$1" = rs ]; then
  for S in 0 1 2; do
    cell=dqn-robust-random-search-fallback-eps0.05$( [ $S = 0 ] || echo "-seed$S" )-100
    $Z evaluate models/dqn-robust --attack random-search --eps 0.05 --patience 10 --target $T --attack-seed $S \
      --episodes 100 --seed 100000 --workers 1 --no-progress --out $A/cells/$cell > $A/cells/$cell.txt 2>&1
  done
elif [ "$1" = pgd ]; then
  for cell in dqn-driver:0.02 dqn-driver:0.05 dqn-robust:0.02; do
    V=${cell%%:*}; E=${cell##*:}
    $Z evaluate models/$V --attack pgd --eps $E --patience 10 --target $T --episodes 100 --seed 100000 --workers 1 \
      --no-progress --out $A/cells/$V-pgd-fallback-eps$E-100 > $A/cells/$V-pgd-fallback-eps$E-100.txt 2>&1
  done
elif [ "$1" = rs-driver ]; then
  if [ "${2:-}" = fallback ]; then cell=dqn-driver-random-search-fallback-eps0.02-100; t="--target $T"
  else cell=dqn-driver-random-search-eps0.02-100; t=""; fi
  $Z evaluate models/dqn-driver --attack random-search --eps 0.02 --patience 10 $t --episodes 100 --seed 100000 \
    --workers 1 --no-progress --out $A/cells/$cell > $A/cells/$cell.txt 2>&1
elif [ "$1" = rs-close ]; then
  cell=dqn-close-random-search-fallback-eps0.02-100
  $Z evaluate models/dqn-close --attack random-search --eps 0.02 --target $T --episodes 100 \
    --seed 100000 --workers 1 --no-progress --out $A/cells/$cell > $A/cells/$cell.txt 2>&1
else
  echo "usage: sh studies/learned-adversary/run-fallback.sh rs|pgd|rs-driver [fallback]|rs-close" >&2; exit 2
fi
