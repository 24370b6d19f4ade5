#!/bin/bash
# models/dqn-close under attack, bare and behind the certified shield: the cells of the shield's v4
# table (studies/shield/run-v4.sh, on models/dqn-driver) on the new driver, and the shield asking for
# close-rules' gap (close-shield), 100 episodes per cell on
# seeds 100000-100099, into results/close-rules/attacked/. Two cells at a time (one per core);
# a cell already complete is skipped by zodrive's resume, so the script can be run again after an
# interruption. Usage: bash studies/close-rules/run-attacks.sh
set -u
cd "$(dirname "$0")/../.."
. .venv/bin/activate
C=results/close-rules/attacked
mkdir -p $C
cell() {  # NAME ARGS...: one evaluation, its command and summary in NAME.txt
  name=$1; shift
  echo "\$ zodrive evaluate models/dqn-close $* --episodes 100 --seed 100000 --workers 1 --out $C/$name" > $C/$name.txt
  zodrive evaluate models/dqn-close "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name --no-progress \
    >> $C/$name.txt 2>&1
}
export -f cell
export C
xargs -P 2 -L 1 bash -c 'cell "$@"' _ <<'EOF'
random-search-eps0.02 --attack random-search --eps 0.02
random-search-eps0.05 --attack random-search --eps 0.05
pgd-eps0.02 --attack pgd --eps 0.02
pgd-eps0.05 --attack pgd --eps 0.05
shield@0.02-none --defense shield@0.02
shield@0.02-pgd-eps0.02 --defense shield@0.02 --attack pgd --eps 0.02
shield@0.02-random-search-eps0.02 --defense shield@0.02 --attack random-search --eps 0.02
shield@0.05-none --defense shield@0.05
shield@0.05-pgd-eps0.05 --defense shield@0.05 --attack pgd --eps 0.05
shield@0.05-random-search-eps0.05 --defense shield@0.05 --attack random-search --eps 0.05
close-shield@0.02-none --defense close-shield@0.02
close-shield@0.02-random-search-eps0.02 --defense close-shield@0.02 --attack random-search --eps 0.02
EOF
# certificates and the per-state sandwich on the states of 10 clean episodes (docs/defenses.md's table)
[ -f results/certify/dqn-close/certify.json ] || zodrive certify models/dqn-close --eps 0.005 0.01 0.02 0.05 \
  --episodes 10 --attack random-search zo-signsgd pgd --out results/certify/dqn-close > $C/certify.txt 2>&1
