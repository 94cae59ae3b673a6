# Sourced by the size reports (footprint.sh, settings-size.sh): finds the tools that read
# ARM ELF files and demangle Rust v0 symbols, and sets SIZE and NM.
#
# Each is $SIZE / $NM when set, else the first found of arm-none-eabi-*, llvm-* (on the
# PATH or in rustup's llvm-tools) and plain size/nm (Debian's binutils). Exits with a
# message naming what it tried when none is found.

pick() {
    local var=$1
    shift
    if [ -n "${!var:-}" ]; then
        echo "${!var}"
        return
    fi
    local sysroot
    sysroot=$(rustc --print sysroot 2>/dev/null || true)
    for tool in "$@"; do
        if command -v "$tool" >/dev/null; then
            command -v "$tool"
            return
        fi
        for found in "$sysroot"/lib/rustlib/*/bin/"$tool"; do
            if [ -x "$found" ]; then
                echo "$found"
                return
            fi
        done
    done
    echo "no $var tool found (tried: $*)" >&2
    exit 1
}
SIZE=$(pick SIZE arm-none-eabi-size llvm-size size)
NM=$(pick NM arm-none-eabi-nm llvm-nm nm)
