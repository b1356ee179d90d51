#!/bin/bash
# usage: bench/tune_diag/held16.sh TREE OUT CORE ["script args:name" ...]: seeded diagnosis sets, one after another,
# pinned to one core; default the held-back sets (free_indep 12, maps 42, multi2 22);
# tally with TALLY_SETS="free_indep12 maps42 m22" python bench/tune_diag/tally.py OUT_A OUT_B
TREE=$1; OUT=$2; CORE=$3; shift 3
SETS=("$@")
[ ${#SETS[@]} -eq 0 ] && SETS=("free_indep.py --seed 12:free_indep12" "maps.py --seed 42:maps42" "multi2.py --seed 22:m22")
PY=${PY:-$(cd "$(dirname "$0")/../.." && pwd)/.venv/bin/python}
export PYTHONPATH=$TREE/src:$TREE/bench OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
mkdir -p $OUT; cd $TREE
for a in "${SETS[@]}"; do
  cmd=${a%%:*}; name=${a##*:}; t0=$(date +%s); mkdir -p $OUT/$name
  nice -n 5 taskset -c $CORE $PY bench/tune_diag/$cmd --out $OUT/$name > $OUT/$name.log 2>&1
  echo "$name rc=$? $(( $(date +%s) - t0 )) s" >> $OUT/times.txt
done
echo done >> $OUT/times.txt
