#!/bin/bash
# usage: bench/tune_diag/fresh28.sh TREE OUT CORE: three seeds no code had run on before session 28
# (multi2 24, maps 44, free_indep 15); tally with TALLY_SETS="free_indep15 maps44 m24" python bench/tune_diag/tally.py A B
TREE=$1; OUT=$2; CORE=$3
PY=${PY:-$(cd "$(dirname "$0")/../.." && pwd)/.venv/bin/python}
export PYTHONPATH=$TREE/src:$TREE/bench OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
mkdir -p $OUT; cd $TREE
for a in "free_indep.py --seed 15:free_indep15" "maps.py --seed 44:maps44" "multi2.py --seed 24:m24"; do
  cmd=${a%%:*}; name=${a##*:}; t0=$(date +%s); mkdir -p $OUT/$name
  nice -n 5 taskset -c $CORE $PY bench/tune_diag/$cmd --out $OUT/$name > $OUT/$name.log 2>&1
  echo "$name rc=$? $(( $(date +%s) - t0 )) s" >> $OUT/times.txt
done
echo done >> $OUT/times.txt
