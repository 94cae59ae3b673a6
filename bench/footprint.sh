#!/usr/bin/env bash
# Flash and RAM of the telemetry stack in a Cortex-M firmware (issue 8, workload 6).
#
#   bash bench/footprint.sh                 # build bench/footprint (STM32F405) and measure it
#   FOOTPRINT_OPT=z bash bench/footprint.sh # the same with opt-level "z"
#   bash bench/footprint.sh path/to/firmware.elf [encoders.elf]
#                                           # measure another ELF (e.g. the STM32F405 example)
#
# Without an ELF argument, builds the firmware in bench/footprint twice (release,
# thumbv7em-none-eabihf): as is, and with the `encoders-only` feature, which links only
# the generated encoders (one out-of-line `encode::<Msg>` per message). The firmware
# speaks PPRZ v2 only: it takes pprz-telemetry and pprz-transports without their default
# features (the other transports). The core's target is 10 KiB (FOOTPRINT_CORE_TARGET).
#
# Method: the ELF's symbols (`nm -S --size-sort -C`), demangled. Build with
# `-C symbol-mangling-version=v0` (bench/footprint/.cargo/config.toml does) so generic
# instances carry their type arguments (`send_to::<..::Gps>`); with legacy mangling the
# per-message table stays empty. Each symbol goes to one bucket:
#   * a generated message (`messages::<class>::<Type>` in the name): that message's
#     code, e.g. the send path monomorphised for it;
#   * an item of a stack crate: its module, `pprz_transports::*` transport,
#     `pprz_telemetry::{arena,queue,downlink,writer,reader|registry|services,stats,...}`,
#     `pprz_messages::*` message layer. Their sum is the stack core;
#   * an item of the application (FOOTPRINT_APP, default pprz_footprint): glue, not
#     counted, except its generic wrappers (FOOTPRINT_WRAPPERS), attributed to the stack
#     module in their type arguments;
#   * library code instantiated for a stack type (`drop_in_place::<FrameBuf>`): that
#     module; anything else (runtime, compiler builtins): not counted.
# Code the compiler inlined into an application function counts as the application's;
# the bench firmware keeps the stack's entry points out of line (tasks polled through a
# generic `poll_task::<Future>`, sends through a generic `send::<Msg>`) so that little
# is lost, and the glue bucket shows how much.
#
# Tools: nm and size that read ARM ELF and demangle Rust v0 symbols, found in this order:
# $NM/$SIZE, arm-none-eabi-nm/-size (Debian: binutils-arm-none-eabi), llvm-nm/llvm-size
# (Debian: llvm), rustup's llvm-tools, plain nm/size (Debian's binutils reads ARM ELF).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)

core_target=${FOOTPRINT_CORE_TARGET:-10240}
msg_target=${FOOTPRINT_MSG_TARGET:-200}
app=${FOOTPRINT_APP:-pprz_footprint}
# Generic functions of the application that only wrap stack code (`poll_task::<Future>`,
# `send::<Msg>`): attributed to what they wrap.
wrappers=${FOOTPRINT_WRAPPERS:-poll_task|send|encode}

# SIZE and NM: tools that read ARM ELF and demangle Rust symbols.
source "$root/bench/elf-tools.sh"

elf=${1:-}
enc_elf=${2:-}
if [ -z "$elf" ]; then
    opt=${FOOTPRINT_OPT:-s}
    target_dir=${FOOTPRINT_TARGET_DIR:-${CARGO_TARGET_DIR:-$root/target}/footprint}
    build() { # $1: variant directory, $2...: cargo flags
        local dir=$1
        shift
        (cd "$root/bench/footprint" &&
            CARGO_PROFILE_RELEASE_OPT_LEVEL=$opt cargo build -q --release \
                --target-dir "$target_dir/$dir" "$@")
        echo "$target_dir/$dir/thumbv7em-none-eabihf/release/pprz-footprint"
    }
    elf=$(build opt-$opt)
    enc_elf=$(build opt-$opt-encoders --features encoders-only)
    echo "firmware: bench/footprint (STM32F405, thumbv7em-none-eabihf, release, opt-level \"$opt\")"
else
    echo "firmware: $elf"
fi
echo "tools: $NM, $SIZE"
echo

# Sections: flash holds the vector table, code, read-only data and the initial values of
# .data; RAM holds .data, .bss and .uninit (the call stack comes on top).
"$SIZE" -A "$elf" | awk '
    $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2 }
    $1 == ".data" { flash += $2; ram += $2 }
    $1 == ".bss" || $1 == ".uninit" { ram += $2 }
    $1 ~ /^\.(vector_table|text|rodata|data|bss|uninit)$/ { printf "  %-14s %7d\n", $1, $2 }
    END { printf "whole firmware: flash %d bytes, static RAM %d bytes\n\n", flash, ram }'

# One line per sized symbol: size (decimal), type, demangled name.
symbols() {
    "$NM" -S -t d --size-sort -C "$1" | awk '
        $2 ~ /^[0-9]+$/ && length($3) == 1 {
            name = $0
            sub(/^[^ ]+ +[^ ]+ +[^ ]+ +/, "", name)
            printf "%d\t%s\t%s\n", $2, $3, name
        }'
}

msg_re='messages::(telemetry|datalink|ground|alert|intermcu)::[A-Z][A-Za-z0-9]*'

symbols "$elf" | awk -F'\t' -v app="$app" -v wrappers="$wrappers" -v core_target="$core_target" \
    -v msg_target="$msg_target" -v msg_re="$msg_re" '
function module(path) {
    if (path ~ /^pprz_transports/) return "transport (pprz_transports)"
    if (path ~ /^pprz_messages/) return "message layer (pprz_messages)"
    sub(/^pprz_telemetry::/, "", path)
    if (path == "arena") return "arena"
    if (path == "queue") return "queue"
    if (path == "downlink") return "downlink send path"
    if (path == "writer") return "writer task"
    if (path == "reader" || path == "registry" || path == "services") return "datalink (reader, registry, services)"
    if (path == "messages") return "message set dispatch"
    return "telemetry " path
}
# The first stack module named anywhere in `name`, or "".
function first_module(name) {
    if (match(name, /pprz_(transports|telemetry|messages)::[a-z_]+/))
        return module(substr(name, RSTART, RLENGTH))
    # Symbols the demangler left alone (e.g. `.Lswitch.table._RNv..15pprz_transports3any..`).
    if (match(name, /[0-9]pprz_(transports|messages)/)) return module(substr(name, RSTART + 1, RLENGTH - 1))
    if (match(name, /[0-9]pprz_telemetry[0-9]+[a-z_]+/)) {
        path = substr(name, RSTART + 1, RLENGTH - 1)
        sub(/pprz_telemetry[0-9]+/, "pprz_telemetry::", path)
        return module(path)
    }
    return ""
}
function bucket(name,    m, owner, crate, mod) {
    if (match(name, msg_re)) {
        m = substr(name, RSTART, RLENGTH)
        sub(/.*::/, "", m)
        if (m != "AnyMessage") return "msg:" m
    }
    # The crate that defines the item: the first path of the name (`<X as T>::f` -> X).
    owner = name
    sub(/^<+/, "", owner)
    crate = match(owner, /^[A-Za-z_][A-Za-z0-9_]*/) ? substr(owner, 1, RLENGTH) : ""
    if (crate ~ /^pprz_(transports|telemetry|messages)$/) return first_module(owner)
    if (crate == app) {
        # The application generic wrappers are named after what they wrap.
        if (owner ~ ("^" app "::(" wrappers ")::<")) {
            mod = first_module(owner)
            if (mod != "") return mod
        }
        return "glue"
    }
    # Library code instantiated for stack types (core::ptr::drop_in_place::<FrameBuf>...).
    mod = first_module(name)
    return mod != "" ? mod : "other"
}
$2 ~ /^[tTrRwWvV]$/ {
    b = bucket($3)
    flash[b] += $1
    count[b]++
}
END {
    printf "stack core, flash (bytes, symbols):\n"
    n = 0
    for (b in flash) if (b != "glue" && b != "other" && b !~ /^msg:/) {
        printf "  %-40s %6d  (%d)\n", b, flash[b], count[b]
        core += flash[b]
    }
    printf "  %-40s %6d  target < %d: %s\n\n", "total", core, core_target,
        core < core_target ? "ok" : sprintf("MISSED by %d", core - core_target)
    printf "per message, flash of everything named after it (send path, decoder):\n"
    for (b in flash) if (b ~ /^msg:/) {
        m = substr(b, 5)
        printf "  %-40s %6d  (%d)\n", m, flash[b], count[b]
        total += flash[b]; msgs++
        if (flash[b] > max) max = flash[b]
    }
    if (msgs) printf "  %d messages: %d bytes, mean %d, max %d\n\n", msgs, total, total / msgs, max
    else printf "  none (no v0-mangled generic instances?)\n\n"
    printf "not counted: application glue %d bytes (%d), runtime and builtins %d bytes (%d)\n\n",
        flash["glue"], count["glue"], flash["other"], count["other"]
}' | awk '
    # Sort the rows of each table by size, largest first.
    /^  / && !/^  total/ && !/messages:/ && !/none/ { rows[++n] = $0; next }
    { flush(); print }
    function flush(   i, j, t) {
        for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++)
            if (size(rows[j]) > size(rows[i])) { t = rows[i]; rows[i] = rows[j]; rows[j] = t }
        for (i = 1; i <= n; i++) print rows[i]
        n = 0
    }
    function size(r,   f) { split(substr(r, 43), f, " "); return f[1] + 0 }
    END { flush() }'

if [ -n "$enc_elf" ]; then
    echo "generated encoders alone (encoders-only build: \`encode::<Msg>\`, incl. a call and a return):"
    symbols "$enc_elf" | sort -t"$(printf '\t')" -k1,1nr | awk -F'\t' -v msg_re="$msg_re" -v msg_target="$msg_target" '
        $3 ~ /::encode::</ && match($3, msg_re) {
            m = substr($3, RSTART, RLENGTH); sub(/.*::/, "", m)
            printf "  %-40s %6d\n", m, $1
            total += $1; n++; if ($1 > max) max = $1
        }
        END {
            if (n) printf "  %d encoders: mean %d, max %d bytes; target < %d per encoder: %s\n\n",
                n, total / n, max, msg_target,
                max < msg_target ? "ok" : sprintf("MISSED by %d", max - msg_target)
        }'
fi

echo "static RAM by symbol (bytes):"
symbols "$elf" | sort -t"$(printf '\t')" -k1,1nr | awk -F'\t' '
    $2 ~ /^[bBdD]$/ && $1 >= 16 { printf "  %-40s %6d\n", substr($3, 1, 40), $1; total += $1 }
    END { printf "  %-40s %6d\n", "total of the above", total }'
