#!/bin/bash
# Issue 23, item 1: three probes of what one query per step can do on the two cells where it stays weaker than
# the per-step searches (dqn-close eps 0.02, dqn-robust eps 0.05); tuning seeds only; printed output beside.
set -u
cd "$(dirname "$0")/../../../.."
. .venv/bin/activate
P=results/learned-adversary/pilots/one-query
A=results/learned-adversary/amortized-dqn-robust-eps0.05
run() {  # OUT SCRIPT ARGS...
  out=$1; shift
  { echo "\$ python $P/$*"; python $P/"$@" 2>&1 | grep -v "^WARN"; } > $P/$out.txt
}
run director-dqn-close director.py models/dqn-close 0.02 &
run director-dqn-robust director.py models/dqn-robust 0.05
wait
run universal-dqn-close universal.py models/dqn-close 0.02 &
run universal-dqn-robust universal.py models/dqn-robust 0.05 --under $A
wait
run closed-loop-dqn-robust closed_loop.py models/dqn-robust 0.05 $A
