#!/bin/bash
# usage: bench/tune_ident/ident125.sh TREE OUT CORE: the 125 identification tuning logs on TREE's code (varied.py seeds
# 1 and 2, two draws, all rates: 108; the widened cases of seed 2: 17), one core, niced. Compare two runs with
# compare_runs.py OUT_A/s1.txt,OUT_A/s2.txt,OUT_A/w2.txt OUT_B/s1.txt,... Held back: the same with a 4th argument "held" (seed 7, 200 and 1000 Hz: OUT/h7.txt).
TREE=$1; OUT=$2; CORE=${3:-0}; MODE=${4:-tune}
PY=${PY:-$(cd "$(dirname "$0")/../.." && pwd)/.venv/bin/python}
export PYTHONPATH=$TREE/src:$TREE/bench OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
mkdir -p $OUT; cd $TREE
run() { nice -n 5 taskset -c $CORE $PY bench/tune_ident/varied.py "$@"; }
if [ "$MODE" = held ]; then
  run --rates 200,1000 --draws 2 --seed 7 > $OUT/h7.txt 2>&1
else
  for s in 1 2; do run --seed $s --draws 2 > $OUT/s$s.txt 2>&1; done
  run --widened --seed 2 > $OUT/w2.txt 2>&1
fi
echo done > $OUT/done
