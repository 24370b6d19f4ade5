#!/usr/bin/env bash
# Issue 22, item 2, continuous side: TD3 from models/ddpg-imitation (recipe td3-finetune), one seed.
# Usage (from the repository root): studies/finetune-continuous/run.sh SEED NAME [--set KEY=VALUE ...]
# Train into runs/td3-finetune/NAME-sSEED, choose a checkpoint on 20 tuning episodes (seeds
# 50000-50019, the start included), evaluate the choice on 100 evaluation episodes (100000-100099).
# The recipe as committed is NAME "init1" (seeds 1000 and 2000 were trained with --steps 20000
# --set guide.name=init --set guide.error=squared --set guide.imitation=1.0 on an earlier version of
# the recipe, which this one equals). "squared" (TD3+BC towards the rules) was the recipe before it:
#   --steps 40000 --set guide.name=rules --set guide.error=squared --set guide.imitation=0.4
set -euo pipefail
seed=$1; name=$2; shift 2
run=runs/td3-finetune/$name-s$seed
out=results/finetune-continuous
[ -f "$run/model.zip" ] || zodrive train --algo td3 --recipe td3-finetune --seed "$seed" --out "$run" --no-progress "$@"
[ -f "$run/selected.json" ] || zodrive select "$run" --episodes 20 --no-progress > "$out/select-$name-s$seed.md"
chosen=$(python -c "import json,sys; print(json.load(open(sys.argv[1]))['selected']['model'])" "$run/selected.json")
zodrive evaluate "$chosen" --episodes 100 --seed 100000 --workers 1 --envs 8 --out "$out/eval-$name-s$seed" \
  --no-progress > "$out/eval-$name-s$seed.txt"
