#!/bin/bash
# The README's test suite, N full runs in a row, beside two busy CPU loops at equal priority
# (issue 22: a healthy program passes on a machine with other work running). Run it from a fresh
# clone, in the foreground or from a job-control shell: a run started under `nohup` or as a
# non-interactive shell's background job inherits ignored SIGHUP/SIGINT/SIGQUIT (the signal tests
# give their child runs default dispositions, the rest of the suite does not need them).
#   bash benchmarks/suite_under_load.sh [RUNS=3] [PYTHON=.venv/bin/python]
# Prints one line per run (start, load average, result); each run's log is /tmp/suite_under_load_N.log.
set -u
cd "$(dirname "$0")/.."
RUNS=${1:-3}
PY=${2:-.venv/bin/python}
python3 -c 'while 1: pass' & H1=$!
python3 -c 'while 1: pass' & H2=$!
trap 'kill -9 $H1 $H2 2>/dev/null' EXIT
for i in $(seq 1 "$RUNS"); do
  echo "run $i start $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) commit $(git log --oneline -1 | cut -c1-8)"
  PYTHONPATH=$PWD "$PY" -m pytest -q -p no:cacheprovider > "/tmp/suite_under_load_$i.log" 2>&1
  rc=$?
  echo "run $i rc $rc end $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) :: $(tail -1 "/tmp/suite_under_load_$i.log")"
  [ $rc -ne 0 ] && exit $rc
done
exit 0
