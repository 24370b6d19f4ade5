#!/bin/bash
# Can a better-fitted surrogate make the fitted start transfer to models/dqn-close? (issue 23)
# Three variants of `attack-train --pretrain-rounds 4` at eps 0.02 beside the committed adversary
# (uniform ball probes, MSE on scores), each evaluated on tuning seeds 900000-900029, with random
# search on the same seeds; adversaries and cells in runs/adv-vert (not committed), printed output in
# results/learned-adversary/pilots/decision-focused.
# The variants use attack-train --pretrain-probe / --pretrain-loss, removed since (docs/attacks.md, "Removed
# options"): run them from a checkout before that (git log -S pretrain-probe); the other cells run on today's zodrive.
set -u
cd "$(dirname "$0")/../../../.."
. .venv/bin/activate
R=runs/adv-vert
D=results/learned-adversary/pilots/decision-focused
ev() {  # NAME ATTACK...: 30 episodes on tuning seeds
  name=$1; shift
  echo "\$ zodrive evaluate models/dqn-close $* --eps 0.02 --episodes 30 --seed 900000 --out $R/$name" > $D/$name.txt
  zodrive evaluate models/dqn-close "$@" --eps 0.02 --episodes 30 --seed 900000 --workers 1 --out $R/$name --no-progress \
    >> $D/$name.txt 2>&1
}
train() {  # NAME OPTIONS...: the fitted start alone (0 PPO steps)
  name=$1; shift
  [ -f $R/$name/model.zip ] && return
  echo "\$ zodrive attack-train models/dqn-close --eps 0.02 --steps 0 --pretrain-rounds 4 --pretrain-episodes 10 $* --reward horizon --out $R/$name" > $D/$name.txt
  zodrive attack-train models/dqn-close --eps 0.02 --steps 0 --pretrain-rounds 4 \
    --pretrain-episodes 10 "$@" --reward horizon --out $R/$name --no-progress >> $D/$name.txt 2>&1
}
ev ball-eval --attack learned:results/learned-adversary/amortized-dqn-close-eps0.02
train vert --pretrain-probe vertices
ev vert-eval --attack learned:$R/vert
train dec --pretrain-loss decisions
ev dec-eval --attack learned:$R/dec
train vd32 --pretrain-probe vertices --pretrain-probes 32 --pretrain-loss decisions
ev vd32-eval --attack learned:$R/vd32
ev rs-eval --attack random-search
ev hold-eval --attack vertex-hold  # 1 query per step (zodrive.attacks.hold), chosen after persistence.sh
python - > $D/paired.txt <<'PY'
import json
from pathlib import Path
from zodrive.evaluation.stats import paired_difference_ci
R = Path("runs/adv-vert")
def returns(cell):
    rows = (json.loads(line) for line in (R / cell / "episodes.jsonl").read_text().splitlines() if line)
    return {row["seed"]: row["return"] for row in rows}
for a, b in [("vert-eval", "ball-eval"), ("dec-eval", "ball-eval"), ("vd32-eval", "ball-eval"),
             ("ball-eval", "rs-eval"), ("vd32-eval", "rs-eval"), ("hold-eval", "rs-eval"), ("hold-eval", "ball-eval")]:
    x, y = returns(a), returns(b)
    seeds = sorted(set(x) & set(y))
    d, lo, hi = paired_difference_ci([x[s] for s in seeds], [y[s] for s in seeds])
    print(f"{a} - {b}: {d:+.2f} [{lo:+.2f}, {hi:+.2f}] over {len(seeds)} seeds")
PY
