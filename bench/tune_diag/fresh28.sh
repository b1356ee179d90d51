#!/bin/bash
# usage: bench/tune_diag/fresh28.sh TREE OUT CORE: three seeds no code had run on before session 28
# (multi2 24, maps 44, free_indep 15); tally with TALLY_SETS="free_indep15 maps44 m24" python bench/tune_diag/tally.py A B
exec "$(dirname "$0")/held16.sh" "$1" "$2" "$3" \
  "free_indep.py --seed 15:free_indep15" "maps.py --seed 44:maps44" "multi2.py --seed 24:m24"
