#!/usr/bin/env bash
# Deterministic instruction counts of the benchmark workloads (issue 8), with callgrind.
#
#   bash bench/callgrind.sh              # every counted mode
#   bash bench/callgrind.sh encode parse # some modes
#
# Builds `workloads` in release (the workspace profile: opt-level "s", LTO, one codegen
# unit), runs each mode under `valgrind --tool=callgrind --toggle-collect=<function>`, so
# only the named workload function and what it calls are counted, and divides the total
# by the count the mode prints on its `units` line. Needs valgrind (Debian: `valgrind`).
#
# The last column is the share of the host's critical sections in that figure (the
# inclusive cost of `critical-section`'s acquire and release, per unit): on the host they
# are `critical-section`'s `std` implementation (a process-wide mutex and a thread-local
# flag, about 50 instructions a pair), on a Cortex-M an interrupt mask of a few
# instructions, so "per unit - host lock" is the stack's own cost.
# Output files stay in $CALLGRIND_DIR (default target/callgrind) for
# `callgrind_annotate --inclusive=yes <file>`.
set -euo pipefail
cd "$(dirname "$0")/.."

modes=("$@")
if [ ${#modes[@]} -eq 0 ]; then
    modes=(encode parse parse-buffered downlink arena-10 arena-50 arena-90 secure-seal secure-open)
fi

command -v valgrind >/dev/null || { echo "valgrind is not installed" >&2; exit 1; }
cargo build -q --release -p pprz-bench --bin workloads
target_dir=$(cargo metadata -q --format-version 1 --no-deps |
    sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
out_dir=${CALLGRIND_DIR:-$target_dir/callgrind}
mkdir -p "$out_dir"

printf '%-24s %-34s %12s %8s  %-18s %s\n' mode function instructions count "per unit" "host lock"
for mode in "${modes[@]}"; do
    # The function that mode measures: workload_<mode>, dashes as underscores.
    function="workload_${mode//-/_}"
    program=workloads
    file="$out_dir/callgrind.out.$mode"
    log="$out_dir/workloads.$mode.txt"
    valgrind --tool=callgrind --callgrind-out-file="$file" \
        --toggle-collect="$program::$function" \
        "$target_dir/release/$program" --mode "$mode" >"$log" 2>"$log.valgrind" ||
        { echo "mode $mode failed: see $log.valgrind" >&2; exit 1; }
    total=$(sed -n 's/^totals: *\([0-9]*\).*/\1/p' "$file")
    read -r _ unit_function count unit < <(grep '^units ' "$log")
    if [ "$unit_function" != "$function" ]; then
        echo "mode $mode: expected units for $function, got $unit_function" >&2
        exit 1
    fi
    if [ -z "$total" ] || [ "$total" -eq 0 ]; then
        echo "mode $mode: nothing counted in $function (renamed or folded?)" >&2
        exit 1
    fi
    per=$(awk -v t="$total" -v c="$count" 'BEGIN { printf "%.1f", t / c }')
    # Inclusive cost of the critical-section functions (their own entries, whose names
    # end with the binary's name in brackets).
    lock=$(callgrind_annotate --inclusive=yes --threshold=100 "$file" 2>/dev/null |
        awk '/:_critical_section_1_0_(acquire|release) \[/ { gsub(",", "", $1); s += $1 }
             END { print s + 0 }')
    lock_per=$(awk -v t="$lock" -v c="$count" 'BEGIN { printf "%.1f", t / c }')
    printf '%-24s %-34s %12s %8s  %-18s %s\n' "$mode" "$function" "$total" "$count" \
        "$per/$unit" "$lock_per"
    if [[ $mode == arena-* ]]; then
        # The allocator alone: the inclusive cost of `alloc` per call and of `release`
        # per release, less one lock (every call takes the arena's lock once), beside the
        # workload loop's own instructions (drawing sizes and victims, its `Vec`).
        read -r allocs releases failed < <(sed -n \
            's/^arena [0-9]* %: \([0-9]*\) allocs, \([0-9]*\) releases, \([0-9]*\) failed.*/\1 \2 \3/p' "$log")
        costs=$(callgrind_annotate --inclusive=yes --threshold=100 "$file" 2>/dev/null |
            awk '# A function is listed once per source file it inlines; its own entry,
                 # the largest, is its inclusive cost.
                 /:pprz_telemetry::arena::FrameArena<M,_>::alloc( \[|$)/ {
                     gsub(",", "", $1); if ($1 + 0 > a) a = $1 + 0 }
                 /:<pprz_telemetry::arena::FrameArena<M,_> as pprz_telemetry::arena::Grants>::release( \[|$)/ {
                     gsub(",", "", $1); if ($1 + 0 > r) r = $1 + 0 }
                 END { print a + 0, r + 0 }')
        read -r alloc_total release_total <<<"$costs"
        awk -v a="$alloc_total" -v r="$release_total" -v na="$((allocs + failed))" \
            -v nr="$releases" -v l="$lock" -v n="$count" 'BEGIN {
                pair = l / n; ca = a / na - pair; cr = r / nr - pair;
                printf "%-24s allocator without the host lock: alloc %.1f, release %.1f, pair %.1f\n",
                    "", ca, cr, ca + cr }'
    fi
done
