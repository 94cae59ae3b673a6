#!/usr/bin/env python3
"""Interrupt-masked instructions of the bench/m4 firmware's traced run.

Reads QEMU's instruction log on standard input (`-d in_asm,exec,nochain -accel
tcg,one-insn-per-tb=on`: each translated block is listed once with its disassembly, then
logged each time it runs) and the firmware's UART output (the file named as the only
argument: its `region <name> <count> <unit> <what>` lines name the regions in order).

Between each `bench_m4_region_begin` and `bench_m4_region_end` call it counts every
instruction executed, and those executed with interrupts masked: from a `cpsid i` that
masks them (PRIMASK was clear) up to and including the instruction that clears PRIMASK
again. cortex-m's single-core critical section saves PRIMASK (`mrs rN, primask`), masks
(`cpsid i`) and on release writes the saved value back (`msr primask, rN`); the log has
no register values, so the script follows the sections as a stack: each `mrs` of
PRIMASK pushes the current state and each `msr` to it pops and restores it, so nested
sections unmask only when the outermost one ends. A `cpsie i` unmasks. The script fails
if the stack does not balance (a PRIMASK read or write that is not a critical section's)
rather than print a wrong figure.

The same for BASEPRI (the `BasepriRawMutex` of pprz-telemetry): from an `msr BASEPRI_MAX`
that raises it (none raised) to the `msr BASEPRI` that writes back the state saved by the
matching `mrs rN, BASEPRI`, followed as a stack in the same way. While BASEPRI is raised,
only the interrupts at or below the ceiling wait; the instructions are reported apart.

Prints, per region: instructions per unit, masked instructions (total, share, per unit),
the number of sections, the longest and the mean, and the functions where the longest
sections start. Exits non-zero if the log has no complete region or the region lines
do not match the markers.
"""

import re
import sys

TRACE = re.compile(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/[0-9a-f]+/[0-9a-f]+\] ?(.*)$")
INSN = re.compile(r"^0x([0-9a-f]+):\s+(?:[0-9a-f]{4}\s?)+\s+(\S+)\s*(.*)$")
BEGIN, END = "bench_m4_region_begin", "bench_m4_region_end"


def demangle(symbol):
    """The path of a legacy-mangled Rust symbol without its hash (enough to read)."""
    if not symbol.startswith("_ZN"):
        return symbol
    parts, i, s = [], 3, symbol
    while i < len(s) and s[i].isdigit():
        j = i
        while s[j].isdigit():
            j += 1
        n = int(s[i:j])
        parts.append(s[j:j + n])
        i = j + n
    if parts and re.fullmatch(r"h[0-9a-f]{16}", parts[-1]):
        parts.pop()
    text = "::".join(parts)
    for code, char in (("$LT$", "<"), ("$GT$", ">"), ("$u20$", " "), ("$C$", ","),
                       ("$u7b$", "{"), ("$u7d$", "}"), ("$RF$", "&"), ("..", "::")):
        text = text.replace(code, char)
    return text


class Region:
    """Counts of one region."""

    def __init__(self):
        self.instructions = 0
        self.masked = 0
        self.sections = 0
        self.longest = 0
        # start function -> (sections, shortest, longest, total)
        self.by_start = {}
        # BASEPRI raised: instructions, sections, longest.
        self.raised = 0
        self.raised_sections = 0
        self.raised_longest = 0

    def section(self, length, start):
        self.sections += 1
        self.masked += length
        self.longest = max(self.longest, length)
        n, shortest, longest, total = self.by_start.get(start, (0, length, 0, 0))
        self.by_start[start] = (n + 1, min(shortest, length), max(longest, length), total + length)

    def raised_section(self, length):
        self.raised_sections += 1
        self.raised += length
        self.raised_longest = max(self.raised_longest, length)


def analyse(log):
    """Regions of the log, in order."""
    blocks = {}  # pc of a translated block -> kinds of its instructions
    pending = None  # the block being listed by in_asm
    regions, region = [], None
    masked, start, start_symbol = False, 0, ""
    saved = []  # PRIMASK states saved by the open critical sections
    raised, raised_start = False, 0  # BASEPRI
    saved_basepri = []  # BASEPRI states saved by the open BASEPRI sections
    unbalanced = 0
    for line in log:
        if line.startswith("IN:"):
            pending = None
            continue
        m = INSN.match(line)
        if m:
            pc = int(m.group(1), 16)
            mnemonic, operands = m.group(2), m.group(3).strip()
            kind = "."
            if mnemonic == "cpsid" and "i" in operands:
                kind = "D"
            elif mnemonic == "cpsie" and "i" in operands:
                kind = "E"
            elif mnemonic == "mrs" and "primask" in operands.lower():
                kind = "R"
            elif mnemonic == "msr" and "primask" in operands.lower():
                kind = "W"
            elif mnemonic == "msr" and "basepri_max" in operands.lower():
                kind = "M"
            elif mnemonic == "mrs" and "basepri" in operands.lower():
                kind = "r"
            elif mnemonic == "msr" and "basepri" in operands.lower():
                kind = "w"
            if pending is None:
                pending = pc
                blocks[pc] = []
            blocks[pending].append(kind)
            continue
        m = TRACE.match(line)
        if not m:
            continue
        pending = None
        pc, symbol = int(m.group(1), 16), m.group(2).strip()
        if symbol == BEGIN:
            if region is None:
                region = Region()
            continue
        if symbol == END:
            if region is not None:
                regions.append(region)
                region = None
            continue
        kinds = blocks.get(pc, ["."])
        for kind in kinds:
            if region is not None:
                region.instructions += 1
            unmask = False
            if kind == "D" and not masked:
                masked, start, start_symbol = True, region.instructions if region else 0, symbol
            elif kind == "E" and masked:
                unmask = True
            elif kind == "R":
                saved.append(masked)
            elif kind == "W":
                if not saved:
                    unbalanced += 1
                elif not saved.pop() and masked:
                    unmask = True
            if unmask:
                masked = False
                if region is not None:
                    region.section(region.instructions - start, demangle(start_symbol))
            lower = False
            if kind == "M" and not raised:
                raised, raised_start = True, region.instructions if region else 0
            elif kind == "r":
                saved_basepri.append(raised)
            elif kind == "w":
                if not saved_basepri:
                    unbalanced += 1
                elif not saved_basepri.pop() and raised:
                    lower = True
            if lower:
                raised = False
                if region is not None:
                    region.raised_section(region.instructions - raised_start)
    return regions, unbalanced + len(saved) + len(saved_basepri)


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: masked.py UART_LOG < QEMU_LOG")
    regions, unbalanced = analyse(sys.stdin)
    names = []
    with open(sys.argv[1], encoding="utf-8", errors="replace") as uart:
        for line in uart:
            fields = line.strip().split(" ", 4)
            if len(fields) >= 4 and fields[0] == "region":
                names.append((fields[1], int(fields[2]), fields[3], fields[4] if len(fields) > 4 else ""))
    if not regions or len(regions) != len(names):
        sys.exit(f"masked.py: {len(regions)} traced regions, {len(names)} region lines")
    if unbalanced:
        sys.exit(f"masked.py: {unbalanced} PRIMASK or BASEPRI writes without a saved state (not a lock's)")
    print("interrupts masked (QEMU instruction log: from the `cpsid i` that masks to the instruction that unmasks):")
    for (name, count, unit, what), r in zip(names, regions):
        share = 100.0 * r.masked / r.instructions if r.instructions else 0.0
        mean = r.masked / r.sections if r.sections else 0.0
        print(f"  {name:<9} {r.instructions / count:9.1f} instructions per {unit:<8}"
              f"masked {r.masked / count:7.1f} per {unit} ({share:4.1f} %), "
              f"{r.sections / count:.2f} sections per {unit}, longest {r.longest}, mean {mean:.1f}"
              f"   ({count} {unit}s: {what})")
        if r.raised_sections:
            share = 100.0 * r.raised / r.instructions
            print(f"      BASEPRI raised {r.raised / count:7.1f} per {unit} ({share:4.1f} %), "
                  f"{r.raised_sections / count:.2f} sections per {unit}, longest {r.raised_longest}, "
                  f"mean {r.raised / r.raised_sections:.1f}: interrupts at or below the ceiling wait")
        worst = sorted(r.by_start.items(), key=lambda kv: -kv[1][2])[:4]
        for start, (n, shortest, longest, total) in worst:
            print(f"      longest {longest:4} mean {total / n:6.1f} shortest {shortest:4} x{n:<6} from {start}")


if __name__ == "__main__":
    main()
