#!/usr/bin/env bash
# What a described setting costs in flash and RAM on an STM32F405 build, and what the
# persistence (pprz-settings, sequential-storage) adds to a firmware.
#
#   bash bench/settings-size.sh     # builds bench/footprint-settings (release), measures it
#
# bench/footprint-settings holds five minimal thumbv7em-none-eabihf firmwares (release:
# opt-level "s", fat LTO, one codegen unit), built by one `cargo build`:
#   * table-0, table-10, table-100: the settings table pprz-codegen generates from a
#     settings.xml of N float settings (17-byte variable names, no short name, unit or
#     labels), registered at boot with the application's bindings (a variable, a getter
#     and a setter per setting, `Binding::Fns`), and served in the main loop (a set and a
#     get by index, as the SETTING and GET_SETTING services do);
#   * store-10, store-100: the same with the boot load and the store task of
#     pprz-settings, over RamFlash (a stand-in for the board's flash driver, whose own
#     code is not counted).
#
# Method: `size -A` of each ELF (flash = .vector_table + .text + .rodata + .data; static
# RAM = .data + .bss + .uninit) and its symbols (`nm -S`, v0-demangled). Per setting:
# the difference between 100 and 10 settings, divided by 90 (the cost of the table's
# own code, present from the first setting on, cancels out). The persistence: store-N
# minus table-N. Fails if a build fails or a symbol it reads is missing.
#
# Tools: size and nm that read ARM ELF and demangle Rust v0 symbols: $SIZE/$NM,
# arm-none-eabi-*, llvm-*, rustup's llvm-tools, or plain size/nm (Debian's binutils).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)

# SIZE and NM: tools that read ARM ELF and demangle Rust symbols.
source "$root/bench/elf-tools.sh"

target_dir=${SETTINGS_SIZE_TARGET_DIR:-${CARGO_TARGET_DIR:-$root/target}/footprint-settings}
(cd "$root/bench/footprint-settings" && cargo build -q --release --target-dir "$target_dir")
bin_dir=$target_dir/thumbv7em-none-eabihf/release
echo "firmwares: bench/footprint-settings (STM32F405, thumbv7em-none-eabihf, release, opt-level \"s\")"
echo "tools: $SIZE, $NM; rustc $(rustc --version | cut -d' ' -f2)"
echo

# `flash ram` of an ELF.
sections() {
    "$SIZE" -A "$1" | awk '
        $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2 }
        $1 == ".data" { flash += $2; ram += $2 }
        $1 == ".bss" || $1 == ".uninit" { ram += $2 }
        END { print flash + 0, ram + 0 }'
}

# The sizes of an ELF's symbols by kind, as `key=value` lines:
#   desc (the SettingDesc array), register (the generated `register`, with the bindings
#   inlined into it), shims (the getters' and setters' Fn, FnMut and FnOnce entries),
#   vtables (anonymous read-only data: their vtables), table (the Settings static),
#   store, control, mem (the flash stand-in's RAM), builtins (memcpy, memmove, memset),
#   rodata_symbols (every sized read-only symbol).
symbols() {
    "$NM" -S -t d -C "$1" | awk '
        NF >= 4 && length($3) == 1 {
            size = $2 + 0; kind = $3
            name = $0; sub(/^[^ ]+ +[^ ]+ +[^ ]+ +/, "", name)
            if (kind ~ /[rR]/) s["rodata_symbols"] += size
            if (name ~ /::settings::SETTINGS$/) s["desc"] += size
            else if (name ~ /^[a-z_0-9]+::register$/) s["register"] += size
            else if (name ~ /::variables::[gs]et_/) s["shims"] += size
            else if (name ~ /^\.Lanon\./ && kind ~ /[rR]/) s["vtables"] += size
            else if (name ~ /^[a-z_0-9]+::TABLE$/) s["table"] += size
            else if (name ~ /^[a-z_0-9]+::STORE$/) s["store"] += size
            else if (name ~ /^[a-z_0-9]+::CONTROL$/) s["control"] += size
            else if (name ~ /^[a-z_0-9]+::MEM$/) s["mem"] += size
            else if (name ~ /compiler_builtins::mem::|^__aeabi_mem/) s["builtins"] += size
        }
        END { for (k in s) print k "=" s[k] }'
}

declare -A flash ram
for fw in table-0 table-10 table-100 store-10 store-100; do
    elf=$bin_dir/$fw
    read -r f r < <(sections "$elf")
    flash[$fw]=$f
    ram[$fw]=$r
    while IFS='=' read -r key value; do
        declare -g "sym_${fw//-/_}_$key=$value"
    done < <(symbols "$elf")
done
# A symbol size read above (0 if the firmware has none).
sym() { local v="sym_${1//-/_}_$2"; echo "${!v:-0}"; }
for fw in table-10 table-100; do
    for key in desc register table; do
        [ "$(sym "$fw" "$key")" -gt 0 ] || { echo "$fw: no $key symbol found" >&2; exit 1; }
    done
done
# Divides by 90, one decimal.
per() { awk -v d="$1" 'BEGIN { printf "%.1f", d / 90 }'; }

printf "%-10s %12s %16s %14s\n" firmware "flash (B)" "static RAM (B)" "table (B)"
for fw in table-0 table-10 table-100 store-10 store-100; do
    note=
    mem=$(sym "$fw" mem)
    [ "$mem" -gt 0 ] && note="  (with the flash stand-in's $mem B)"
    printf "%-10s %12d %16d %14d%s\n" "$fw" "${flash[$fw]}" "${ram[$fw]}" "$(sym "$fw" table)" "$note"
done
echo

echo "per described setting, from 10 to 100 settings (difference / 90):"
printf "  %-58s %7s B\n" "flash, in all" "$(per $((flash[table-100] - flash[table-10])))"
rodata_10=$("$SIZE" -A "$bin_dir/table-10" | awk '$1 == ".rodata" { print $2 }')
rodata_100=$("$SIZE" -A "$bin_dir/table-100" | awk '$1 == ".rodata" { print $2 }')
strings_10=$((rodata_10 - $(sym table-10 rodata_symbols)))
strings_100=$((rodata_100 - $(sym table-100 rodata_symbols)))
d() { echo $(($(sym table-100 "$1") - $(sym table-10 "$1"))); }
printf "  %-58s %7s B\n" "  descriptor (SettingDesc)" "$(per "$(d desc)")"
printf "  %-58s %7s B\n" "  variable name string (read-only data without a symbol)" "$(per $((strings_100 - strings_10)))"
printf "  %-58s %7s B\n" "  registration (generated register, bindings built)" "$(per "$(d register)")"
printf "  %-58s %7s B\n" "  getter and setter (Fn, FnMut, FnOnce entries)" "$(per "$(d shims)")"
printf "  %-58s %7s B\n" "  their two vtables" "$(per "$(d vtables)")"
printf "  %-58s %7s B\n" "static RAM, in all" "$(per $((ram[table-100] - ram[table-10])))"
printf "  %-58s %7s B\n" "  table entry (Option<SettingEntry>)" "$(per "$(d table)")"
printf "  %-58s %7s B\n" "  the variable (the application's AtomicU32)" \
    "$(per $((ram[table-100] - ram[table-10] - $(d table))))"
echo

echo "persistence: store-N minus table-N (pprz-settings, sequential-storage, the boot load"
echo "and the store task, RamFlash; not the board's flash driver):"
for n in 10 100; do
    fl=$((flash[store-$n] - flash[table-$n]))
    bi=$(($(sym "store-$n" builtins) - $(sym "table-$n" builtins)))
    rm=$((ram[store-$n] - ram[table-$n] - $(sym "store-$n" mem)))
    printf "  %3d settings: flash %6d B, of which %d B compiler builtins (memcpy, memmove, memset);\n" \
        "$n" "$fl" "$bi"
    printf "                static RAM %d B: the store %d B (StaticCell), StoreControl %d B\n" \
        "$rm" "$(sym "store-$n" store)" "$(sym "store-$n" control)"
done
echo "  (the boot load's and the store task's futures are on main's stack here; an executor"
echo "  keeps the task's in its task pool)"
