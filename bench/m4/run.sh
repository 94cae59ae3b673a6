#!/usr/bin/env bash
# Instruction counts on an emulated Cortex-M4: builds the bench/m4 firmware (release:
# opt-level "s", fat LTO, one codegen unit), runs it on QEMU's mps2-an386 with
# `-icount shift=0` (1 ns of virtual time per guest instruction, so the board's 25 MHz
# timers tick once per 40 instructions), and prints the figures: the encode, parse and
# downlink workloads of the host benchmarks (issue 16: instructions per message / per
# byte), the secure link's handshake steps and per-frame work (issue 14), each also in
# ms on a 168 MHz Cortex-M4 (STM32F405) assuming one instruction per cycle (an
# approximation: loads, taken branches and flash wait states cost more), the persistent
# settings' boot load and store of 100 settings (per setting, and the total), then the
# firmware's flash.
#
#   bash bench/m4/run.sh          # from anywhere; a few seconds once built
#
# Needs: rustup target thumbv7em-none-eabihf, qemu-system-arm (QEMU >= 6: mps2-an386,
# semihosting), and a `size` that reads ARM ELF (arm-none-eabi-size, llvm-size, or
# Debian's binutils `size`). Fails if the firmware fails, QEMU does not stop within
# $BENCH_M4_TIMEOUT seconds (default 60), or the clock calibration is not 40.
set -euo pipefail
cd "$(dirname "$0")"

qemu=${QEMU:-qemu-system-arm}
timeout_s=${BENCH_M4_TIMEOUT:-60}
command -v "$qemu" >/dev/null || { echo "$qemu is not installed" >&2; exit 1; }

# BENCH_M4_TARGET=thumbv6m-none-eabi: the same firmware as ARMv6-M code (the instruction
# set of a Cortex-M0/M0+, without compare-and-swap), which the Cortex-M4 also runs.
target=${BENCH_M4_TARGET:-thumbv7em-none-eabihf}
cargo build -q --release --target "$target"
target_dir=$(cargo metadata -q --format-version 1 --no-deps |
    sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
elf=$target_dir/$target/release/bench-m4

log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
timeout "$timeout_s" "$qemu" -M mps2-an386 -nographic -monitor none -serial stdio \
    -icount shift=0 -semihosting-config enable=on,target=native \
    -kernel "$elf" </dev/null >"$log" 2>&1 || status=$?
tr -d '\r' <"$log" >"$log.txt" && mv "$log.txt" "$log"
if [ "$status" -ne 0 ] || ! grep -qx done "$log"; then
    cat "$log" >&2
    if [ "$status" -eq 124 ]; then
        echo "QEMU did not stop within ${timeout_s} s" >&2
    else
        echo "the firmware failed (QEMU exit status $status)" >&2
    fi
    exit 1
fi
# Both clocks must count one tick per 40 instructions (-icount shift=0, 25 MHz).
if [ "$(grep -c '= 40.000 instructions/tick' "$log")" -ne 2 ]; then
    cat "$log" >&2
    echo "calibration: not 40 instructions per tick" >&2
    exit 1
fi

awk '
    /^result / {
        name = $2; instructions = $3; count = $4; unit = $5
        what = $6; for (i = 7; i <= NF; i++) what = what " " $i
        per = instructions / count
        printf "  %-16s %12.*f instructions per %-9s %9.4f ms at 168 MHz   %s", name,
            (unit == "byte" ? 2 : 1), per, unit, per / 168000, what
        if (unit == "frame") printf " (%d frames: %d instructions; %.1f per field byte)", count, instructions, per / 40
        else if (count > 1) printf " (%d %ss: %d instructions)", count, unit, instructions
        printf "\n"
        next
    }
    { print }
' "$log"

# The masked-interrupt figures: a second run of the same firmware (semihosting argument
# `masked`: a few workloads on 1000 messages each, between markers) with QEMU logging
# every instruction it executes (one instruction per translated block, no chaining),
# read as it is written by masked.py (about 500 MB of log, never stored).
uart=$(mktemp)
trap 'rm -f "$log" "$uart"' EXIT
status=0
timeout $((timeout_s * 4)) "$qemu" -M mps2-an386 -nographic -monitor none -serial "file:$uart" \
    -semihosting-config enable=on,target=native,arg=bench-m4,arg=masked \
    -accel tcg,one-insn-per-tb=on -d in_asm,exec,nochain -D /dev/stdout \
    -kernel "$elf" </dev/null | python3 masked.py "$uart" || status=$?
if [ "$status" -ne 0 ] || ! tr -d '\r' <"$uart" | grep -qx done; then
    tr -d '\r' <"$uart" >&2
    echo "the masked-interrupt run failed (status $status)" >&2
    exit 1
fi

size_tool=
for t in ${SIZE:-} arm-none-eabi-size llvm-size size; do
    if command -v "$t" >/dev/null; then size_tool=$t; break; fi
done
if [ -n "$size_tool" ]; then
    echo "flash ($size_tool -A $elf): vector table + .text + .rodata + .data"
    "$size_tool" -A "$elf" | awk '
        $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" || $1 == ".data" {
            printf "  %-14s %8d\n", $1, $2; total += $2
        }
        $1 == ".bss" || $1 == ".uninit" { ram += $2 }
        END { printf "  %-14s %8d bytes (static RAM %d bytes)\n", "flash", total, ram }'
else
    echo "flash: no size tool (arm-none-eabi-size, llvm-size or size) found" >&2
fi
