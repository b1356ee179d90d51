#!/bin/bash
# usage: bench/tune_diag/runsets.sh TREE OUTDIR [CORE] [SETS...]: the diagnosis tuning sets on TREE's code, pinned to one
# core (taskset), niced, one process; OUTDIR/times.txt gets a line per set (wall seconds). PY overrides the python.
# Compare two trees by running both side by side, one core each, then: python bench/tune_diag/tally.py OUT_A OUT_B
# SETS default: all. Names: cases loads combos other_pairs maps free_noise free_quiet free_indep11 free_indep13 multi2
# deadzones drifts modes forms3 datasets
TREE=$1; OUT=$2; CORE=${3:-1}; shift $(( $# < 3 ? $# : 3 ))
SETS=${@:-cases loads combos other_pairs maps free_noise free_quiet free_indep11 free_indep13 multi2 deadzones drifts modes forms3 datasets}
PY=${PY:-$(cd "$(dirname "$0")/../.." && pwd)/.venv/bin/python}
export PYTHONPATH=$TREE/src:$TREE/bench OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
mkdir -p $OUT
for s in $SETS; do
  t0=$(date +%s)
  case $s in
    cases) a="$TREE/bench/tune_diag/cases.py --seed 7";;
    loads) a="$TREE/bench/tune_diag/loads.py --seed 3";;
    combos) a="$TREE/bench/tune_diag/combos.py --seed 21";;
    other_pairs) a="$TREE/bench/tune_diag/other_pairs.py --seed 5";;
    maps) a="$TREE/bench/tune_diag/maps.py --seed 41";;
    free_noise) a="$TREE/bench/tune_diag/free_noise.py --seed 3";;
    free_quiet) a="$TREE/bench/tune_diag/free_noise.py --seed 3 --quiet";;
    free_indep11) a="$TREE/bench/tune_diag/free_indep.py --seed 11";;
    free_indep13) a="$TREE/bench/tune_diag/free_indep.py --seed 13";;
    multi2) a="$TREE/bench/tune_diag/multi2.py --seed 21";;
    deadzones) a="$TREE/bench/tune_diag/deadzones.py --seed 1";;
    drifts) a="$TREE/bench/tune_diag/drifts.py --seed 1";;
    modes) a="$TREE/bench/tune_diag/modes.py --seed 1";;
    forms3) a="$TREE/bench/tune_diag/forms3.py --seed 1";;
    datasets) (cd $TREE && nice -n 5 taskset -c $CORE $PY bench/tune_diag/datasets.py > $OUT/datasets.log 2>&1); echo "datasets rc=$? $(( $(date +%s) - t0 )) s" >> $OUT/times.txt; continue;;
  esac
  mkdir -p $OUT/$s
  (cd $TREE && nice -n 5 taskset -c $CORE $PY $a --out $OUT/$s > $OUT/$s.log 2>&1); rc=$?
  echo "$s rc=$rc $(( $(date +%s) - t0 )) s" >> $OUT/times.txt
done
echo done >> $OUT/times.txt
