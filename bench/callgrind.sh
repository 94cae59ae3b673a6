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

printf '%-24s %-34s %12s %8s  %s\n' mode function instructions count "per unit"
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
    printf '%-24s %-34s %12s %8s  %s/%s\n' "$mode" "$function" "$total" "$count" "$per" "$unit"
done
