#!/usr/bin/env bash
# frames/s of `sonotrace dataset` (bench/specs/dataset_scaling.json, or $SPEC), alternating
# A B, B A, ... ($PAIRS pairs, default 2):
#   bench/dataset_scaling.sh           A: 1 rank x 2 threads, B: 2 ranks x 1 thread
#   FIXED=1 bench/dataset_scaling.sh   A: the spec with depth and gain fixed
#                                      (dataset_scaling_fixed.json, or $FIXED_SPEC), B: the
#                                      spec as it is, both 1 rank x 2 threads
# (from a Release build in build/, Open MPI installed)
cd "$(dirname "$0")/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
spec=${SPEC:-bench/specs/dataset_scaling.json}
fixed=${FIXED_SPEC:-bench/specs/dataset_scaling_fixed.json}
frames=$(python3 -c "import json;print(json.load(open('$spec'))['frames'])")
run() {
  rm -rf /tmp/dsb; local t0=$(date +%s.%N)
  if [ "${FIXED:-0}" = 1 ]; then
    if [ "$1" = A ]; then build/sonotrace dataset $fixed --out /tmp/dsb -q --threads 2
    else build/sonotrace dataset $spec --out /tmp/dsb -q --threads 2; fi
  elif [ "$1" = A ]; then build/sonotrace dataset $spec --out /tmp/dsb -q --threads 2
  else mpirun -n 2 build/sonotrace dataset $spec --out /tmp/dsb -q --threads 1; fi
  local t1=$(date +%s.%N); python3 -c "print('%.3f' % ($frames / ($t1 - $t0)))"
}
for pair in $(seq ${PAIRS:-2}); do
  if [ $((pair % 2)) = 1 ]; then a=$(run A); b=$(run B); else b=$(run B); a=$(run A); fi
  echo "pair $pair: A $a frames/s, B $b frames/s, ratio $(python3 -c "print('%.3f' % ($b / $a))")"
done
