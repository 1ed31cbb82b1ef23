#!/usr/bin/env python3
"""Flash / RAM / stack report of libbeaconloc in the Cortex-M4F example.

Reads the linker map (library share of every output section), the ELF
(whole image), the sizes of bl_filter, bl_sequencer and bl_localizer (nm -S of
the probe object sim/size_probe.o; the example's one localizer is fw_loc), the
-fstack-usage .su files (worst function) and the -fcallgraph-info=su .ci
files (worst call chain). Prints a table and, last, one machine-readable
line:

  size-m4 lib_flash_bytes=<n> lib_ram_bytes=<n> newlib_flash_bytes=<n>
          image_flash_bytes=<n> image_ram_bytes=<n> filter_bytes=<n>
          sequencer_bytes=<n> localizer_bytes=<n> stack_fn_max_bytes=<n>
          stack_chain_max_bytes=<n>
          heap_refs=<number of heap functions linked>
"""
import argparse
import glob
import os
import re
import subprocess
import sys

FLASH_SECTIONS = {".isr_vector", ".text", ".ARM.extab", ".ARM.exidx", ".preinit_array",
                  ".init_array", ".fini_array"}
RAM_SECTIONS = {".bss"}
BOTH_SECTIONS = {".data"}  # load image in flash, copy in RAM

TARGET_FLASH = 32 * 1024
TARGET_FILTER_RAM = 2 * 1024
TARGET_STACK = 2 * 1024


def map_shares(map_path):
    """Bytes per (owner, output section) from the 'Linker script and memory map' part."""
    text = open(map_path, encoding="utf-8", errors="replace").read()
    start = text.find("Linker script and memory map")
    if start < 0:
        sys.exit(f"size_report: {map_path}: no memory map")
    lines = text[start:].splitlines()
    out_sec = None
    shares = {}
    pending_name = None
    in_re = re.compile(r"^\s+0x[0-9a-f]+\s+0x([0-9a-f]+)\s+(\S.*)$")
    for line in lines:
        m_out = re.match(r"^(\.[A-Za-z_.]+)\s*(0x[0-9a-f]+)?", line)
        if m_out and not line.startswith(" "):
            out_sec = m_out.group(1)
            pending_name = None
            continue
        m_one = re.match(r"^ (\.\S+|COMMON)\s+0x[0-9a-f]+\s+0x([0-9a-f]+)\s+(\S.*)$", line)
        if m_one:
            size, owner = int(m_one.group(2), 16), m_one.group(3)
        else:
            m_name = re.match(r"^ (\.\S+|COMMON)\s*$", line)
            if m_name:
                pending_name = m_name.group(1)
                continue
            m_in = in_re.match(line)
            if not (m_in and pending_name):
                continue
            size, owner = int(m_in.group(1), 16), m_in.group(2)
            pending_name = None
        if out_sec is None or size == 0:
            continue
        if "libbeaconloc.a" in owner:
            who = "lib"
        elif re.search(r"lib(c_nano|m|g_nano|gcc|nosys)\.a", owner):
            who = "newlib"
        else:
            who = "example"
        shares[(who, out_sec)] = shares.get((who, out_sec), 0) + size
    return shares


def flash_ram(shares, who):
    flash = sum(v for (w, s), v in shares.items() if w == who and (s in FLASH_SECTIONS or s in BOTH_SECTIONS))
    ram = sum(v for (w, s), v in shares.items() if w == who and (s in RAM_SECTIONS or s in BOTH_SECTIONS))
    return flash, ram


def elf_totals(prefix, elf):
    out = subprocess.run([prefix + "size", elf], check=True, capture_output=True, text=True).stdout
    text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
    return text + data, data + bss


def symbol_size(prefix, elf, name):
    out = subprocess.run([prefix + "nm", "-S", elf], check=True, capture_output=True, text=True).stdout
    for line in out.splitlines():
        f = line.split()
        if len(f) == 4 and f[3] == name:
            return int(f[1], 16)
    sys.exit(f"size_report: symbol {name} not in {elf}")


def heap_symbols(prefix, elf):
    out = subprocess.run([prefix + "nm", elf], check=True, capture_output=True, text=True).stdout
    names = {line.split()[-1] for line in out.splitlines() if line.strip()}
    return sorted(names & {"malloc", "free", "calloc", "realloc", "_malloc_r", "_free_r"})


def read_su(dirs):
    """[(bytes, kind, function, file)] from every .su file."""
    rows = []
    for d in dirs:
        for path in sorted(glob.glob(os.path.join(d, "*.su"))):
            for line in open(path, encoding="utf-8"):
                parts = line.rstrip("\n").split("\t")
                if len(parts) != 3:
                    continue
                rows.append((int(parts[1]), parts[2], parts[0], os.path.basename(path)))
    return rows


def read_ci(dirs):
    """Call graph: node -> own stack bytes, node -> callees, plain name -> node."""
    own, calls, by_name, dynamic = {}, {}, {}, set()
    node_re = re.compile(r'node: \{ title: "([^"]+)" label: "([^"]*)"')
    edge_re = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')
    for d in dirs:
        for path in sorted(glob.glob(os.path.join(d, "*.ci"))):
            for line in open(path, encoding="utf-8"):
                m = node_re.search(line)
                if m:
                    title, label = m.group(1), m.group(2)
                    m_b = re.search(r"\\n(\d+) bytes \(([^)]*)\)", label)
                    if m_b:  # defined here
                        own[title] = int(m_b.group(1))
                        if "dynamic" in m_b.group(2):
                            dynamic.add(title)
                        by_name[title.split(":")[-1]] = title
                        calls.setdefault(title, [])
                    continue
                m = edge_re.search(line)
                if m:
                    calls.setdefault(m.group(1), []).append(m.group(2))
    return own, calls, by_name, dynamic


def worst_chain(root, own, calls, by_name):
    """(bytes, path, external callees) of the deepest stack from root; a
    recursive cycle is reported as such (unbounded)."""
    memo = {}
    externals = set()

    def resolve(n):
        if n in own:
            return n
        return by_name.get(n.split(":")[-1])

    def visit(n, stack):
        if n in memo:
            return memo[n]
        if n in stack:
            raise RecursionError(" -> ".join(stack + [n]))
        best = (0, [])
        for callee in calls.get(n, []):
            r = resolve(callee)
            if r is None:
                externals.add(callee)  # newlib / libgcc: not measured here
                continue
            sub = visit(r, stack + [n])
            if sub[0] > best[0]:
                best = sub
        res = (own.get(n, 0) + best[0], [n] + best[1])
        memo[n] = res
        return res

    total, path = visit(root, [])
    return total, path, externals


DEMANGLE_PREFIX = "arm-none-eabi-"


def short(node):
    """Readable function name: demangled, without arguments and templates."""
    name = re.sub(r"^[^:]+\.(c|cc|cpp):", "", node)
    name = name.split(" [with ")[0].split(" [clone ")[0]
    if name.startswith("_Z"):
        base = name.split(".")[0]
        try:
            name = subprocess.run([DEMANGLE_PREFIX + "c++filt", base], check=True, capture_output=True,
                                  text=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return name
    # drop argument lists and template arguments (nested)
    out, depth = [], 0
    for ch in name:
        if ch in "<(":
            depth += 1
        elif ch in ">)":
            depth -= 1
        elif depth == 0:
            out.append(ch)
    name = "".join(out).replace("{anonymous}::", "").replace("{lambda", "lambda").replace("}", "")
    name = name.strip()
    if name.endswith(" const"):
        name = name[: -len(" const")]
    return name.split(" ")[-1] if " " in name else name


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--elf", required=True)
    ap.add_argument("--map", required=True)
    ap.add_argument("--lib-objs", required=True)
    ap.add_argument("--example-objs", required=True)
    ap.add_argument("--prefix", default="arm-none-eabi-")
    ap.add_argument("--probe", required=True, help="object defining size_probe_{filter,sequencer,localizer}")
    a = ap.parse_args()
    global DEMANGLE_PREFIX
    DEMANGLE_PREFIX = a.prefix

    shares = map_shares(a.map)
    lib_flash, lib_ram = flash_ram(shares, "lib")
    nl_flash, nl_ram = flash_ram(shares, "newlib")
    ex_flash, ex_ram = flash_ram(shares, "example")
    img_flash, img_ram = elf_totals(a.prefix, a.elf)
    filt = symbol_size(a.prefix, a.probe, "size_probe_filter")
    seq = symbol_size(a.prefix, a.probe, "size_probe_sequencer")
    loc = symbol_size(a.prefix, a.probe, "size_probe_localizer")

    su = read_su([a.lib_objs])
    su.sort(reverse=True)
    fn_max = su[0] if su else (0, "static", "-", "-")
    own, calls, by_name, dynamic = read_ci([a.lib_objs, a.example_objs])
    chain_main, path_main, ext_main = worst_chain("main", own, calls, by_name)
    lib_entries = sorted(n for n in own if n.startswith("bl_"))
    lib_chain = (0, [], set())
    for n in lib_entries:
        c = worst_chain(n, own, calls, by_name)
        if c[0] > lib_chain[0]:
            lib_chain = c

    def verdict(v, lim):
        return "ok" if v <= lim else "OVER"

    print("Cortex-M4F (float32, -Os, newlib nano), STM32F407 example lib/examples/firmware_m4")
    print(f"  library flash (text+rodata+data)   {lib_flash:7d} B   target <= {TARGET_FLASH} B  {verdict(lib_flash, TARGET_FLASH)}")
    print(f"  library RAM (data+bss, globals)    {lib_ram:7d} B")
    print(f"  newlib/libgcc pulled in by all     {nl_flash:7d} B flash, {nl_ram} B RAM")
    print(f"  example code (board, main, start) {ex_flash:7d} B flash, {ex_ram} B RAM")
    print(f"  whole image                        {img_flash:7d} B flash, {img_ram} B RAM (data+bss)")
    print(f"  sizeof(bl_localizer)               {loc:7d} B   target <= {TARGET_FILTER_RAM} B  {verdict(loc, TARGET_FILTER_RAM)}")
    print(f"    of which bl_filter               {filt:7d} B")
    print(f"    of which bl_sequencer            {seq:7d} B")
    print(f"    policy, events, pulse scratch    {loc - filt - seq:7d} B")
    print(f"  worst library function stack       {fn_max[0]:7d} B   {short(fn_max[2].split(':', 3)[-1])} ({fn_max[1]})")
    print(f"  worst library call chain           {lib_chain[0]:7d} B   target <= {TARGET_STACK} B  {verdict(lib_chain[0], TARGET_STACK)}")
    print("      " + " -> ".join(short(n) for n in lib_chain[1]))
    print(f"  worst chain from main (incl. ISR-free example) {chain_main} B")
    print("      " + " -> ".join(short(n) for n in path_main))
    if dynamic:
        print("  dynamic stack in: " + ", ".join(sorted(short(n) for n in dynamic)))
    ext = sorted(set(short(e) for e in (ext_main | lib_chain[2])))
    print("  not counted (newlib/libgcc, no .ci): " + ", ".join(ext))
    print("  top library functions by stack:")
    for row in su[:5]:
        where, sig = row[2].split(":", 3)[:3], row[2].split(":", 3)[-1]
        print(f"      {row[0]:5d} B  {short(sig)}  ({where[0]}:{where[1]})")
    heap = heap_symbols(a.prefix, a.elf)
    print("  heap functions linked: " + (", ".join(heap) if heap else "none"))
    print(f"size-m4 lib_flash_bytes={lib_flash} lib_ram_bytes={lib_ram} newlib_flash_bytes={nl_flash} "
          f"image_flash_bytes={img_flash} image_ram_bytes={img_ram} filter_bytes={filt} sequencer_bytes={seq} localizer_bytes={loc} "
          f"stack_fn_max_bytes={fn_max[0]} stack_chain_max_bytes={lib_chain[0]} heap_refs={len(heap)}")


if __name__ == "__main__":
    main()
