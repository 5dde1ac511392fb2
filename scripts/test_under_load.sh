#!/usr/bin/env bash
# Run the whole test suite N times in a row with one core kept busy by another process, as a loaded lab
# machine or a shared CI runner would be: `scripts/test_under_load.sh [N]` (default 5).
# Each run is `make test` (set-up included); its log goes to LOGDIR/run_<i>.log (default /tmp/rimd-under-load).
# Prints one line per run (exit status, duration, pytest's summary) and exits non-zero if any run failed.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)"
RUNS="${1:-5}"
LOGDIR="${LOGDIR:-/tmp/rimd-under-load}"
mkdir -p "$LOGDIR"
cd "$ROOT" || exit 1

# The load: one busy process, pinned to nothing (the scheduler moves it like any other job).
python3 -c "while True: pass" &
BUSY=$!
trap 'kill "$BUSY" 2>/dev/null' EXIT
# Ctrl-C or SIGTERM ends the series (a bare trap would only stop the busy loop and go on to the next run).
trap 'exit 130' INT TERM

failed=0
for i in $(seq 1 "$RUNS"); do
    start=$(date +%s)
    make test PYTEST_ARGS="-p no:cacheprovider" >"$LOGDIR/run_$i.log" 2>&1
    rc=$?
    summary="$(grep -E '[0-9]+ (passed|failed)' "$LOGDIR/run_$i.log" | tail -1)"
    echo "run $i/$RUNS: exit $rc in $(( $(date +%s) - start )) s: $summary"
    [ "$rc" -eq 0 ] || failed=$((failed + 1))
done
echo "$((RUNS - failed)) of $RUNS runs green under load (logs in $LOGDIR)"
[ "$failed" -eq 0 ]
