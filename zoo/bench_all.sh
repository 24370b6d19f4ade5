#!/usr/bin/env bash
# Select every finished zoo run's checkpoint on tuning seeds, then bench it and the baselines of its
# scenario under the official protocol into results/bench (resumable: finished cells are kept).
# Run: OMP_NUM_THREADS=1 nohup bash zoo/bench_all.sh > zoo/bench.log 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."
for scenario in highway-fast merge roundabout intersection; do
  for run in models/zoo/$scenario-dqn*/seed-*; do  # every DQN family (merge-dqn-g99: row dqn-g99-seed-N)
    [ -f "$run/model.zip" ] || [ -f "$run/final.zip" ] || continue
    family=$(basename "$(dirname "$run")")
    python zoo/choose_checkpoint.py "$run" --scenario "$scenario"
    zodrive bench "$run" --scenario "$scenario" --name "${family#"$scenario"-}-$(basename "$run")" --no-progress
  done
  for run in models/zoo/$scenario-attention/seed-*; do  # zoo/ego_attention.py: a network zodrive does not rebuild
    [ -f "$run/model.zip" ] || [ -f "$run/final.zip" ] || continue
    PYTHONPATH=zoo python zoo/choose_checkpoint.py "$run" --scenario "$scenario" --trust-model --from-step 42000 --episodes 100  # after exploration; 100 episodes: studies/zoo-recipe
    PYTHONPATH=zoo zodrive bench "$run" --scenario "$scenario" --name "attention-$(basename "$run")" --trust-model --no-progress
  done
  for run in models/zoo/$scenario-attention-ensemble/seed-*; do  # zoo/q_ensemble.py: built, no checkpoint to choose
    [ -f "$run/model.zip" ] || continue
    PYTHONPATH=zoo zodrive bench "$run" --scenario "$scenario" --name "attention-ensemble-$(basename "$run")" --trust-model --no-progress
  done
  for run in models/zoo/$scenario-imitation/seed-*; do  # zoo/imitate.sh: no checkpoint to choose
    [ -f "$run/model.zip" ] || continue
    zodrive bench "$run" --scenario "$scenario" --name "imitation-$(basename "$run")" --no-progress
  done
  for baseline in slower idle faster rules brake-escape idm-mobil planner; do
    zodrive bench "baseline:$baseline" --scenario "$scenario" --name "baseline-$baseline" --no-progress \
      || echo "baseline:$baseline does not drive $scenario"
  done
done
zodrive leaderboard --out docs/leaderboard.md --plot docs/leaderboard.png
