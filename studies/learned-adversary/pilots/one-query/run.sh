#!/bin/bash
# Issue 23, item 1: three probes of what one query per step can do on the two cells where it stays weaker than
# the per-step searches (dqn-close eps 0.02, dqn-robust eps 0.05); tuning seeds only; printed output in
# results/learned-adversary/pilots/one-query.
set -u
cd "$(dirname "$0")/../../../.."
. .venv/bin/activate
S=studies/learned-adversary/pilots/one-query
P=results/learned-adversary/pilots/one-query
A=results/learned-adversary/amortized-dqn-robust-eps0.05
run() {  # OUT SCRIPT ARGS...
  out=$1; shift
  { echo "\$ python $S/$*"; python $S/"$@" 2>&1 | grep -v "^WARN"; } > $P/$out.txt
}
run director-dqn-close director.py models/dqn-close 0.02 &
run director-dqn-robust director.py models/dqn-robust 0.05
wait
run universal-dqn-close universal.py models/dqn-close 0.02 &
run universal-dqn-robust universal.py models/dqn-robust 0.05 --under $A
wait
run closed-loop-dqn-robust closed_loop.py models/dqn-robust 0.05 $A
# The harm on dqn-robust at eps 0.05 is FASTER, not "any action but braking" (--target not:SLOWER), even for
# random search: vertex hold and random search with either target, 30 tuning episodes, in runs/avoid (not committed)
evaluate() {  # OUT ATTACK TARGET [OPTIONS...]
  out=$1 attack=$2 target=$3; shift 3
  cmd="zodrive evaluate models/dqn-robust --attack $attack --eps 0.05 $* --target $target --episodes 30 --seed 900000 --workers 1 --no-progress --out runs/avoid/$out"
  { echo "\$ $cmd"; $cmd 2>&1; } > $P/avoid-$out.txt
}
evaluate hold-robust-0.05 vertex-hold not:SLOWER
evaluate rs-robust-0.05-FASTER random-search FASTER --patience 10
evaluate rs-robust-0.05-not-SLOWER random-search not:SLOWER --patience 10
# Do the fitted start's three training seeds reach FASTER on different states? One query per step: the next
# adversary takes over after a miss (2026-11-26)
run ensemble-dqn-robust ensemble.py models/dqn-robust 0.05 $A $A-seed1 $A-seed2
# Is braking what keeps the fitted start (with the fallback) weaker than random search on dqn-robust at eps 0.05?
# Vertex hold for "not braking" after the adversary misses (or after the victim brakes), one query per step
# (2026-11-26, second session)
F=results/learned-adversary/amortized-fallback-dqn-robust-eps0.05
run switch-miss-dqn-robust switch.py models/dqn-robust 0.05 $F --m 1 3 10 --trigger miss
run switch-brake-dqn-robust switch.py models/dqn-robust 0.05 $F --m 1 3 --trigger brake
# Where a picker misses on dqn-close at eps 0.02, does its pool of 64 random vertices hold one that works?
run pool-dqn-close pool.py models/dqn-close 0.02 results/vertex-hold/picker/dqn-close-eps0.02-seed0
# Six pickers (three BCE and three rank fits) with their ratings averaged, on tuning seeds and then on the
# evaluation seeds, paired against random search
K=results/vertex-hold/picker
{ run pickers-tuning pickers.py models/dqn-close 0.02 $K/dqn-close-eps0.02-seed{0,1,2} $K/dqn-close-rank-eps0.02-seed{0,1,2} --alone
  run pickers-eval pickers.py models/dqn-close 0.02 $K/dqn-close-eps0.02-seed{0,1,2} $K/dqn-close-rank-eps0.02-seed{0,1,2} \
    --episodes 100 --seed0 100000 --paired results/close-rules/attacked/random-search-eps0.02; }
# On random search's own states (with the fallback), where does the fitted start (with the fallback) reach FASTER?
run critical-dqn-robust critical.py models/dqn-robust 0.05 $F --episodes 30
