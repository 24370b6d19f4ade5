# Sourced by run.sh and run-check.sh (with C set to the cells folder): `cell ATTACK NAME MODEL ARGS...` runs one
# evaluation, 100 episodes on seeds 100000-100099, into $C/NAME, with its command and summary in $C/NAME.txt.
cell() {
  attack=$1; name=$2; model=$3; shift 3
  echo "\$ zodrive evaluate $model --attack $attack $* --episodes 100 --seed 100000 --out $C/$name" > $C/$name.txt
  zodrive evaluate $model --attack $attack "$@" --episodes 100 --seed 100000 --workers 1 --out $C/$name \
    --no-progress >> $C/$name.txt 2>&1
}
