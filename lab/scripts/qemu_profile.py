#!/usr/bin/env python3
"""Where the firmware's instructions go: a flat profile of episodes run under QEMU.

Runs `activesense sim --link qemu:ELF ...` with QEMU's `-d in_asm,exec,nochain` trace written
to a FIFO, and books every executed translation block's guest instructions to the function
QEMU names for it (the ELF's symbols; inlined code counts in its caller). Entries into a
function are counted where a block starts at the function's address, and the function
that ran just before is booked as its caller. `-icount shift=0` is on, as in `mcu-bench`
(it also translates shortened blocks at the same address, so blocks are told apart by
their translation, not their address). This is how the libm trigonometry and square roots
were found (README, "Instructions per update"): a trace, not a sample, so the same on
every run.

Usage (the sim's own options after `--`):
    python3 lab/scripts/qemu_profile.py [--top 40] [--callers 12] -- \
        --first-seed 1000000 --episodes 3 --agent learnt --rot-bins 10 --termination confident

Slow (QEMU writes one line per executed block): about 30 s per K = 10 episode.
"""
import argparse
import collections
import os
import subprocess
import sys
import tempfile
import threading

ELF = "target/thumbv7em-none-eabihf/firmware/activesense-firmware"
CLI = "target/release/activesense"


def symbols(elf):
    """Function start addresses (Thumb bit cleared) -> name, from llvm-nm."""
    out = subprocess.run(
        ["llvm-nm", "-n", "--defined-only", elf], capture_output=True, text=True, check=True
    ).stdout
    starts = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1] in "tTwW":
            starts[int(parts[0], 16) & ~1] = parts[2]
    return starts


def aggregate(path, starts, result):
    # A block is known by QEMU's translation (its host address, the trace's first field):
    # under -icount QEMU also translates shortened blocks at the same guest address.
    blocks = {}  # translation -> (instructions, function)
    own = collections.Counter()
    calls = collections.Counter()
    callers = collections.defaultdict(collections.Counter)
    total = 0
    prev = "?"
    name, first, n = None, None, 0
    fresh = None  # the block just translated: (pc, instructions, function)
    with open(path, errors="replace") as f:
        for line in f:
            if line.startswith("Trace"):
                tb = line.split()[2]
                pc = int(line.split("[", 1)[1].split("/")[1], 16)
                if fresh is not None and fresh[0] == pc:
                    blocks[tb] = fresh[1:]
                    fresh = None
                k, fn = blocks.get(tb, (0, "?"))
                own[fn] += k
                total += k
                if pc in starts:
                    calls[starts[pc]] += 1
                    callers[starts[pc]][prev] += 1
                prev = fn
            elif line.startswith("IN:"):
                name, first, n = line[3:].strip() or "?", None, 0
            elif name is not None and line.startswith("0x"):
                if first is None:
                    first = int(line.split(":")[0], 16)
                n += 1
            elif name is not None and not line.strip():
                if first is not None:
                    fresh = (first, n, name)
                name = None
    result.update(own=own, calls=calls, callers=callers, total=total)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--elf", default=ELF)
    ap.add_argument("--top", type=int, default=40, help="functions listed")
    ap.add_argument("--callers", type=int, default=12, help="most-called functions whose callers are listed")
    ap.add_argument("sim_args", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    sim_args = a.sim_args[1:] if a.sim_args[:1] == ["--"] else a.sim_args
    for path in (a.elf, CLI):
        if not os.path.exists(path):
            sys.exit(f"{path} not found: build it first (`cargo xtask firmware`, `cargo build --release -p activesense-sim`)")
    starts = symbols(a.elf)
    tmp = tempfile.mkdtemp()
    fifo = os.path.join(tmp, "trace")
    os.mkfifo(fifo)
    result = {}
    reader = threading.Thread(target=aggregate, args=(fifo, starts, result))
    reader.start()
    qemu = ["-icount", "shift=0", "-d", "in_asm,exec,nochain", "-D", fifo]
    cmd = [CLI, "sim", "--link", f"qemu:{a.elf}"] + [f"--qemu-arg={q}" for q in qemu] + sim_args
    sim = subprocess.run(cmd, capture_output=True, text=True)
    reader.join()
    if sim.returncode != 0:
        sys.exit(f"sim failed:\n{sim.stderr[-2000:]}")
    total = result["total"]
    print(f"# {total} guest instructions: {' '.join(sim_args)}\n")
    print("| instructions | share | entries | function |\n|---:|---:|---:|---|")
    for fn, k in result["own"].most_common(a.top):
        print(f"| {k} | {100 * k / total:.1f} % | {result['calls'].get(fn, 0)} | `{fn}` |")
    print()
    for fn, c in result["calls"].most_common(a.callers):
        who = ", ".join(f"{w} ×{m}" for w, m in result["callers"][fn].most_common(6))
        print(f"- `{fn}` ({c} entries) from: {who}")


if __name__ == "__main__":
    main()
