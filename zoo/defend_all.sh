#!/usr/bin/env bash
# Make the zoo's defended systems and bench them into results/bench (docs/bench.md, "Defended rows"):
# each scenario's best driver made robust by SA-DQN's regularizer and by adversarial training (the
# paper's Algorithm 2) at eps 0.05, 20,000 more steps each (the zoo's three seeds on highway-fast, where
# issue 64's goal is; the one best seed elsewhere), and the driver behind each inference-time defense that
# reads that scenario: the shield on highway-fast and merge (it reads the lanes of baseline:rules), the
# randomized smoothing and the temporal median on all four. Zoo DQNs are pickled SB3 zips: --trust-model.
# Runs after zoo/train_all.sh and zoo/bench_all.sh (the undefended rows every defended row is read
# against); finished runs and rows are skipped, so it resumes. Then: python zoo/card.py.
# Run: OMP_NUM_THREADS=1 nohup bash zoo/defend_all.sh > zoo/defend.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."

robust() {  # SCENARIO DRIVER SEED: SA and AT from the driver, each benched as a plain model and checked exactly
  local scenario=$1 driver=$2 seed=$3
  for method in sa at; do
    local out="models/zoo/$scenario-$method/seed-$seed"
    [ -f "$out/model.zip" ] || zodrive robust-train "$driver" --method "$method" --eps 0.05 --steps 20000 \
      --seed "$seed" --out "$out" --no-progress --trust-model
    zodrive bench "$out" --scenario "$scenario" --name "$method-seed-$seed" --no-progress
    local row="results/bench/$scenario/$method-seed-$seed" states=100 limit=10
    [ "$method" = sa ] && states=30 limit=3  # SA's MILPs are the slow ones (docs/bench.md, "The exact check")
    [ -f "$row/exact.json" ] || zodrive certify "$out" --row "$row" --states "$states" --time-limit "$limit"
  done
}

defended() {  # SCENARIO DRIVER NAME DEFENSE: the driver behind an inference-time defense
  zodrive bench "$2" --scenario "$1" --defense "$4" --name "$3+$4" --trust-model --no-progress
}

for seed in 0 1 2; do
  robust highway-fast "models/zoo/highway-fast-dqn/seed-$seed" "$seed"
  defended highway-fast "models/zoo/highway-fast-dqn/seed-$seed" "dqn-seed-$seed" shield@0.05
done
defended highway-fast models/zoo/highway-fast-dqn/seed-0 dqn-seed-0 smooth@0.02
defended highway-fast models/zoo/highway-fast-dqn/seed-0 dqn-seed-0 temporal@3
robust merge models/zoo/merge-dqn-g99/seed-0 0
for defense in shield@0.05 smooth@0.02 temporal@3; do
  defended merge models/zoo/merge-dqn-g99/seed-0 dqn-g99-seed-0 "$defense"
done
robust roundabout models/zoo/roundabout-dqn/seed-1 0
robust intersection models/zoo/intersection-dqn/seed-2 0
for defense in smooth@0.02 temporal@3; do
  defended roundabout models/zoo/roundabout-dqn/seed-1 dqn-seed-1 "$defense"
  defended intersection models/zoo/intersection-dqn/seed-2 dqn-seed-2 "$defense"
done
zodrive leaderboard --out docs/leaderboard.md --plot docs/leaderboard.png --frontier docs/frontier.png --force
