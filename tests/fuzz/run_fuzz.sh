#!/bin/sh
# Run libFuzzer harnesses one after the other and print one summary line each:
#   fuzz <name> seconds=<s> runs=<n> exec_per_s=<n> cov=<n> ft=<n> corpus=<n> new=<n> rss_mb=<n> crashes=<0|1> elapsed_s=<n>
# (cov/ft: libFuzzer's edge and feature coverage at the end of the run;
# corpus: units in the run's corpus, seeds included; seconds: the time
# limit, elapsed_s: the time taken). Exits 1 if any
# harness crashed (its log tail and the saved input are shown).
# Usage: run_fuzz.sh --seconds S --build DIR NAME[:RUNS]...
#   DIR/fuzz_NAME         the harness
#   tests/fuzz/corpus/NAME  committed seeds (read only)
#   DIR/corpus/NAME       new units (written)
#   DIR/artifacts/NAME/   crashing inputs;  DIR/logs/NAME.log  the full log
# NAME alone explores for S seconds from a random seed, starting from the
# seeds and what earlier runs found: the way to find new defects.
# NAME:RUNS is the smoke run of `make test`: RUNS inputs from the fixed seed
# --seed (default 1) on the committed seeds alone (a wiped DIR/smoke/NAME
# takes the new units), so its outcome depends on the code and the
# committed corpus, never on the machine's speed or an earlier run; S only
# bounds its time.
set -u
seconds=60
build=build/fuzz
seed=1
while [ $# -gt 0 ]; do
    case $1 in
    --seconds) seconds=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    *) break ;;
    esac
done
here=$(dirname "$0")
failed=0
summary=""
for arg in "$@"; do
    name=${arg%%:*}
    runs=
    [ "$name" != "$arg" ] && runs=${arg#*:}
    bin=$build/fuzz_$name
    seeds=$here/corpus/$name
    work=$build/corpus/$name
    art=$build/artifacts/$name
    log=$build/logs/$name.log
    if [ -n "$runs" ]; then
        work=$build/smoke/$name
        rm -rf "$work"
    fi
    mkdir -p "$work" "$art" "$build/logs"
    set -- -max_total_time="$seconds" -print_final_stats=1 -timeout=10 \
        -rss_limit_mb=2048 -artifact_prefix="$art/"
    # The smoke run also without address-space randomisation: libFuzzer's
    # stack-depth features follow the stack's address, and with it the
    # same seed took other paths from run to run.
    norand=
    if [ -n "$runs" ]; then
        set -- "$@" -runs="$runs" -seed="$seed" -reload=0
        setarch "$(uname -m)" -R true 2>/dev/null && norand="setarch $(uname -m) -R"
    fi
    t_start=$(date +%s)
    [ -f "$here/$name.dict" ] && set -- "$@" -dict="$here/$name.dict"
    [ -f "$build/$name.dict" ] && set -- "$@" -dict="$build/$name.dict"
    [ -f "$here/$name.options" ] && set -- "$@" $(cat "$here/$name.options")
    ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1} \
    UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1} \
        $norand "$bin" "$@" "$work" "$seeds" > "$log" 2>&1
    rc=$?
    elapsed=$(( $(date +%s) - t_start ))
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
    line="fuzz $name seconds=$seconds runs=$(stat number_of_executed_units) exec_per_s=$(stat average_exec_per_sec) cov=${cov:-0} ft=${ft:-0} corpus=${corp:-0} new=$(stat new_units_added) rss_mb=$(stat peak_rss_mb) crashes=$crashes elapsed_s=$elapsed"
    echo "$line"
    summary="$summary$line
"
done
printf 'fuzz summary (%s s each):\n%s' "$seconds" "$summary"
exit $failed
