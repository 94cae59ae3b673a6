#!/usr/bin/env bash
# Flash of the secure layer's parts on thumbv7em-none-eabihf (STM32F405), issue 14.
#
#   bash secure/size-check/measure.sh            # opt-level "s" (the workspace's release)
#   OPT=z bash secure/size-check/measure.sh      # opt-level "z"
#   SHA2=unroll bash secure/size-check/measure.sh # sha2's default unrolled SHA-512
#
# Builds this firmware once per feature set (release, fat LTO) and prints its flash
# (.vector_table + .text + .rodata + .data) and the difference from the empty firmware.
# Parts share code (SHA-512 inside Ed25519, field arithmetic between X25519 and
# Ed25519), so the parts do not add up to the whole: the "all" lines are the truth.
# pprz-secure's own code is the aircraft line minus the "all primitives" line of the
# same backend. The empty firmware already links memcpy/memmove/memset, as any
# firmware with the telemetry stack does.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here"
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$here/../../target-secure/size-check}
export CARGO_PROFILE_RELEASE_OPT_LEVEL=${OPT:-s}
SIZE=${SIZE:-$(command -v arm-none-eabi-size || command -v llvm-size || command -v size)}
elf=$CARGO_TARGET_DIR/thumbv7em-none-eabihf/release/pprz-secure-size-check

# sha2 unrolls SHA-512's 80 rounds by default (about 29 KB on Cortex-M4); a firmware
# selects the rolled loop with `--cfg sha2_backend_soft="compact"` in its rustflags.
sha2=${SHA2:-compact}
cfg=()
if [ "$sha2" = compact ]; then
    cfg=(--config 'target.thumbv7em-none-eabihf.rustflags=["--cfg","sha2_backend_soft=\"compact\""]')
fi

flash() {
    rm -f "$elf"
    cargo build --release -q "${cfg[@]}" ${1:+--features "$1"} >&2
    "$SIZE" -A "$elf" | awk '/^\.(vector_table|text|rodata|data) / { s += $2 } END { print s }'
}

base=$(flash "")
printf '%-58s %8s %8s\n' "part (opt-level ${OPT:-s}, sha2 $sha2)" flash "+empty"
row() {
    local n
    n=$(flash "$2")
    printf '%-58s %8d %8d\n' "$1" "$n" $((n - base))
}
printf '%-58s %8d %8d\n' "empty firmware (cortex-m-rt, panic-halt, memcpy/memmove)" "$base" 0
row "ChaCha20-Poly1305 (encrypt + decrypt)" aead
row "SHA-512 (sha2)" sha512
row "X25519 (x25519-dalek)" x25519
row "Ed25519 sign (ed25519-dalek, from seed)" ed25519-sign
row "Ed25519 verify (ed25519-dalek, strict)" ed25519-verify
row "Ed25519 sign + verify (ed25519-dalek)" ed25519-sign,ed25519-verify
row "all primitives, RustCrypto + dalek" aead,sha512,x25519,ed25519-sign,ed25519-verify
row "pprz-secure aircraft (channel, responder, keys), dalek" secure-dalek
row "SHA-512 (salty)" salty-sha512
row "X25519 (salty)" salty-x25519
row "Ed25519 sign (salty)" salty-sign
row "Ed25519 verify (salty)" salty-verify
row "Ed25519 sign + verify + X25519 (salty)" salty-sign,salty-verify,salty-x25519
row "all primitives, RustCrypto AEAD + salty" aead,salty-sign,salty-verify,salty-x25519
row "pprz-secure aircraft (channel, responder, keys), salty" secure-salty
