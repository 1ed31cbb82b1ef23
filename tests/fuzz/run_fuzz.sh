#!/bin/sh
# Run libFuzzer harnesses one after the other and print one summary line each:
#   fuzz <name> seconds=<s> runs=<n> exec_per_s=<n> cov=<n> ft=<n> corpus=<n> new=<n> rss_mb=<n> crashes=<0|1>
# (cov/ft: libFuzzer's edge and feature coverage at the end of the run;
# corpus: units in the run's corpus, seeds included). Exits 1 if any
# harness crashed (its log tail and the saved input are shown).
# Usage: run_fuzz.sh --seconds S --build DIR NAME...
#   DIR/fuzz_NAME         the harness
#   tests/fuzz/corpus/NAME  committed seeds (read only)
#   DIR/corpus/NAME       new units (written)
#   DIR/artifacts/NAME/   crashing inputs;  DIR/logs/NAME.log  the full log
set -u
seconds=60
build=build/fuzz
while [ $# -gt 0 ]; do
    case $1 in
    --seconds) seconds=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    *) break ;;
    esac
done
here=$(dirname "$0")
failed=0
summary=""
for name in "$@"; do
    bin=$build/fuzz_$name
    seeds=$here/corpus/$name
    work=$build/corpus/$name
    art=$build/artifacts/$name
    log=$build/logs/$name.log
    mkdir -p "$work" "$art" "$build/logs"
    set -- -max_total_time="$seconds" -print_final_stats=1 -timeout=10 \
        -rss_limit_mb=2048 -artifact_prefix="$art/"
    [ -f "$here/$name.dict" ] && set -- "$@" -dict="$here/$name.dict"
    [ -f "$build/$name.dict" ] && set -- "$@" -dict="$build/$name.dict"
    [ -f "$here/$name.options" ] && set -- "$@" $(cat "$here/$name.options")
    ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1} \
    UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1} \
        "$bin" "$@" "$work" "$seeds" > "$log" 2>&1
    rc=$?
    # Final stats and the last status line ("#N DONE cov: C ft: F corp: U/..").
    stat() { sed -n "s/^stat::$1: *\([0-9]*\).*/\1/p" "$log" | tail -n 1; }
    last=$(grep -E '^#[0-9]+[[:space:]]+[A-Z]+[[:space:]]+cov:' "$log" | tail -n 1)
    cov=$(printf '%s\n' "$last" | sed -n 's/.* cov: \([0-9]*\).*/\1/p')
    ft=$(printf '%s\n' "$last" | sed -n 's/.* ft: \([0-9]*\).*/\1/p')
    corp=$(printf '%s\n' "$last" | sed -n 's/.* corp: \([0-9]*\).*/\1/p')
    crashes=0
    if [ $rc -ne 0 ]; then
        crashes=1
        failed=1
        echo "== fuzz_$name FAILED (exit $rc); log $log; saved input:" >&2
        sed -n 's/.*Test unit written to \(.*\)/  \1/p' "$log" >&2
        grep -v '^#[0-9]' "$log" | tail -n 40 >&2
    fi
    line="fuzz $name seconds=$seconds runs=$(stat number_of_executed_units) exec_per_s=$(stat average_exec_per_sec) cov=${cov:-0} ft=${ft:-0} corpus=${corp:-0} new=$(stat new_units_added) rss_mb=$(stat peak_rss_mb) crashes=$crashes"
    echo "$line"
    summary="$summary$line
"
done
printf 'fuzz summary (%s s each):\n%s' "$seconds" "$summary"
exit $failed
