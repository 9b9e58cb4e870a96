# GraspGuide: post-build report of the bare-metal ELF (extra_scripts of [env:cortex_m4f]).
# Runs after every build, with binutils only:
#   1. flash and static RAM split into the core (graspguide:: and the Eigen code it
#      instantiates), the device application, the harness and its platform
#      (src/harness/size/, src/platform/cortex_m/) and the C/C++ runtime, from the
#      linker map (every input section, padding included);
#   2. runtime helpers worth knowing about on this target (heap, soft-float double,
#      stdio, exceptions) and which graspguide functions reach them;
#   3. the worst-case stack depth from Reset_Handler, from -fcallgraph-info=su (.ci
#      files) plus prologue estimates for library functions compiled without it.
# It only reports: it never fails the build.
import collections
import glob
import os
import re
import subprocess

Import("env")  # noqa: F821 (SCons)

FLASH_SECTIONS = (
    ".isr_vector",
    ".text",
    ".rodata",
    ".ARM.extab",
    ".ARM.exidx",
    ".preinit_array",
    ".init_array",
    ".fini_array",
)
RAM_SECTIONS = (".data", ".bss")


def _run(env, tool, *args):
    exe = env.subst("$%s" % tool) if tool.isupper() else "arm-none-eabi-" + tool
    return subprocess.run([exe, *args], check=True, capture_output=True, text=True).stdout


def _demangle(names):
    if not names:
        return {}
    out = subprocess.run(
        ["arm-none-eabi-c++filt"],
        input="\n".join(names),
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split("\n")
    return dict(zip(names, out))


def _short(name, width=110):
    """Demangled name with template arguments collapsed, for one-line output."""
    depth, out = 0, []
    name = name.replace("(anonymous namespace)", "{anon}")
    for ch in name:
        if ch == "<":
            if depth == 0:
                out.append("<..>")
            depth += 1
        elif ch == ">":
            depth = max(0, depth - 1)
        elif depth == 0:
            out.append(ch)
    s = "".join(out)
    s = re.sub(r"\(.*\)", "()", s)  # drop parameter lists
    return s if len(s) <= width else s[: width - 3] + "..."


# --- 1. ownership of every byte, from the map ------------------------------------
def _namespace(symbol):
    """First two namespace components of an Itanium-mangled name, e.g. ('graspguide',
    'device'); ('', '') for C names."""
    m = re.match(r"_ZN[KVrRO]*(?:St)?(\d+)", symbol)
    if not m:
        return ("std", "") if symbol.startswith("_ZSt") else ("", "")
    parts, pos = [], m.start(1)
    while len(parts) < 2:
        m = re.match(r"(\d+)", symbol[pos:])
        if not m:
            break
        n = int(m.group(1))
        start = pos + len(m.group(1))
        parts.append(symbol[start : start + n])
        pos = start + n
    parts += [""] * (2 - len(parts))
    return tuple(parts)


SOFT_DOUBLE = re.compile(r"^(__aeabi_(d\w+|[fil]2d|ul2d|l2d)|__\w+df\d?\w*)$")


def _category(section, obj):
    sym = re.sub(r"^\.(text|rodata|data|bss)(\.rel\.ro)?\.", "", section)
    ns = _namespace(sym)
    if ns[0] == "graspguide":
        return "device app" if ns[1] == "device" else "core (graspguide)"
    if ns[0] == "Eigen":
        return "core (Eigen)"
    # The image's own sources: src/harness/size/ and the src/platform/cortex_m/ it links.
    if re.search(r"(^|/)src/(harness|platform)/", obj):
        return "harness + platform"
    if "libgraspguide_device" in obj:
        return "device app"
    if "libgraspguide" in obj:
        return "core (graspguide)"
    base = os.path.basename(obj)
    if SOFT_DOUBLE.match(sym) or re.search(
        r"_(arm_)?(addsub|muldiv|cmp|fixdfdi|fixunsdfdi|"
        r"fixunsdfsi|fixdfsi|floatdidf|floatundidf)df",
        base,
    ):
        return "runtime: soft double"
    if "libm" in obj:
        return "runtime: libm"
    if "libgcc" in obj:
        return "runtime: libgcc"
    if "libc" in obj or "libg_nano" in obj:
        return "runtime: libc (newlib-nano)"
    if "libstdc++" in obj or "libsupc++" in obj:
        return "runtime: libstdc++"
    return "other"


def parse_map(path):
    """[(output_section, input_section, address, size, object)] of allocated sections."""
    rows = []
    with open(path, encoding="utf8", errors="replace") as fp:
        lines = fp.read().split("\n")
    try:
        start = lines.index("Linker script and memory map")
    except ValueError:
        return rows
    out_sec, pending = None, None
    for line in lines[start + 1 :]:
        m = re.match(r"^(\.[\w.]+)\s+0x[0-9a-f]+\s+0x[0-9a-f]+", line)
        if m or re.match(r"^\.[\w.]+$", line):
            out_sec = m.group(1) if m else line.strip()
            pending = None
            continue
        if out_sec not in FLASH_SECTIONS + RAM_SECTIONS:
            continue
        m = re.match(
            r"^ (\*fill\*|[.\w$]\S*)?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)(?:\s+(\S.*))?$", line
        )
        if m and (m.group(1) or pending):
            name = m.group(1) or pending
            size = int(m.group(3), 16)
            obj = (m.group(4) or "").strip()
            if name == "*fill*":
                obj = "(padding)"
            if size:
                rows.append((out_sec, name, int(m.group(2), 16), size, obj))
            pending = None
            continue
        m = re.match(r"^ ([.\w$]\S*)$", line)
        pending = m.group(1) if m else None
    return rows


def ownership(rows):
    flash = collections.Counter()
    ram = collections.Counter()
    fill = {"flash": 0, "ram": 0}
    last_cat = {}
    for out_sec, name, _addr, size, obj in rows:
        if obj == "(padding)":
            cat = last_cat.get(out_sec, "other")  # alignment of the preceding section
        else:
            cat = _category(name, obj)
            last_cat[out_sec] = cat
        if out_sec in FLASH_SECTIONS or out_sec == ".data":
            flash[cat] += size
        if out_sec in RAM_SECTIONS:
            ram[cat] += size
    return flash, ram, fill


# --- 2. call graph of the linked code (disassembly) -------------------------------
def call_graph(env, elf):
    dis = _run(env, "objdump", "-d", "--no-show-raw-insn", elf)
    callers = collections.defaultdict(set)
    callees = collections.defaultdict(set)
    prologue = {}
    cur, first = None, 0
    for line in dis.split("\n"):
        m = re.match(r"^[0-9a-f]+ <(.+)>:$", line)
        if m:
            cur, first = m.group(1), 0
            prologue[cur] = 0
            continue
        if cur is None or not line.startswith(" "):
            continue
        first += 1
        if first <= 6:  # stack the prologue reserves: push, vpush, sub sp
            p = re.search(r"\s(push|stmdb\s+sp!,)\s*\{([^}]*)\}", line)
            v = re.search(r"\svpush\s*\{([^}]*)\}", line)
            s = re.search(r"\ssub(?:\.w)?\s+sp,\s*(?:sp,\s*)?#(\d+)", line)
            if p:
                prologue[cur] += 4 * _reg_count(p.group(2))
            elif v:
                prologue[cur] += (8 if "d" in v.group(1) else 4) * _reg_count(v.group(1))
            elif s:
                prologue[cur] += int(s.group(1))
        m = re.search(r"\s(?:bl|blx|b|b\.w|b\.n)(?:\w\w)?(?:\.w|\.n)?\s+[0-9a-f]+ <([^>+]+)>", line)
        if m and m.group(1) != cur:
            callers[m.group(1)].add(cur)
            callees[cur].add(m.group(1))
    return callers, callees, prologue


def _reg_count(reglist):
    count = 0
    for item in reglist.split(","):
        item = item.strip()
        m = re.match(r"[rsd](\d+)-[rsd](\d+)", item)
        count += int(m.group(2)) - int(m.group(1)) + 1 if m else (1 if item else 0)
    return count


HELPERS = [
    ("heap (malloc)", re.compile(r"^(malloc|_malloc_r|calloc|realloc|_sbrk|_Zna?[jm]\w*)$")),
    ("soft-float double", SOFT_DOUBLE),
    (
        "stdio/printf",
        re.compile(
            r"^(_?v?f?i?printf|_?v?s?n?i?printf(_r)?|_svfi?printf_r|"
            r"_vfi?printf_r|puts|fputs|_puts_r|__sfvwrite_r|_fwalk\w*)$"
        ),
    ),
    (
        "C++ exceptions/unwinding",
        re.compile(
            r"^(__cxa_throw|__cxa_allocate_exception|"
            r"__gxx_personality_v0|_Unwind_\w+|"
            r"__aeabi_unwind_cpp_pr\d)$"
        ),
    ),
    ("iostream/locale", re.compile(r"^_ZNS[it]|^_ZSt4cout|^_ZNSt6locale")),
]


def helper_report(callers, symbols):
    lines = []
    names = set(symbols)
    for label, pattern in HELPERS:
        present = sorted(n for n in names if pattern.match(n))
        if not present:
            lines.append("  %-26s none linked" % (label + ":"))
            continue
        # Nearest graspguide (or harness) functions that reach these helpers.
        users, seen = set(), set()
        todo = list(present)
        while todo:
            n = todo.pop()
            for c in callers.get(n, ()):
                if c in seen:
                    continue
                seen.add(c)
                if _namespace(c)[0] == "graspguide" or c in ("main", "m4f_reset_continue"):
                    users.add(c)
                else:
                    todo.append(c)
        dem = _demangle(sorted(users))
        size_note = ", ".join(present[:6]) + (" ..." if len(present) > 6 else "")
        lines.append("  %-26s LINKED: %s" % (label + ":", size_note))
        for u in sorted(set(_short(dem.get(u, u)) for u in users)):
            lines.append("      reached from %s" % u)
    return lines


# --- 3. worst-case stack ------------------------------------------------------------
def parse_callgraph_info(build_dir):
    frames, edges, dynamic = {}, collections.defaultdict(set), set()
    virtuals = set()
    for path in glob.glob(os.path.join(build_dir, "**", "*.ci"), recursive=True):
        with open(path, encoding="utf8", errors="replace") as fp:
            text = fp.read()
        for m in re.finditer(r'^node: \{ title: "([^"]+)" label: "([^"]*)"', text, re.M):
            title = m.group(1).split(":", 1)[-1] if ":" in m.group(1) else m.group(1)
            f = re.search(r"\\n(\d+) bytes \(([^)]*)\)", m.group(2))
            if f:
                frames[title] = max(frames.get(title, 0), int(f.group(1)))
                if "dynamic" in f.group(2):
                    dynamic.add(title)
            if m.group(2).startswith("virtual "):
                virtuals.add(title)
        for m in re.finditer(r'^edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"', text, re.M):
            src = m.group(1).split(":", 1)[-1]
            dst = m.group(2).split(":", 1)[-1] if m.group(2) != "__indirect_call" else m.group(2)
            edges[src].add(dst)
    return frames, edges, dynamic, virtuals


def worst_stack(root, frames, edges, virtuals, asm_callees, prologue, skip=None):
    memo, on_path, notes = {}, set(), set()

    def frame(fn):
        if fn in frames:
            return frames[fn]
        if fn in prologue:
            notes.add("prologue")
            return prologue[fn]
        notes.add("unknown:" + fn)
        return 0

    def succ(fn):
        if fn in edges:
            out = set()
            for d in edges[fn]:
                out |= virtuals if d == "__indirect_call" else {d}
            return out
        return asm_callees.get(fn, set())  # library code: calls seen in the disassembly

    def depth(fn):
        if fn in memo:
            return memo[fn]
        if fn in on_path:
            notes.add("recursion:" + fn)
            return (0, [])
        on_path.add(fn)
        best = (0, [])
        for s in succ(fn):
            if skip and skip.search(s):
                continue
            d = depth(s)
            if d[0] > best[0]:
                best = d
        on_path.discard(fn)
        memo[fn] = (frame(fn) + best[0], [fn] + best[1])
        return memo[fn]

    return depth(root), notes


def report(target, source, env):  # pylint: disable=unused-argument
    elf = str(source[0])
    build_dir = env.subst("$BUILD_DIR")
    map_path = os.path.splitext(elf)[0] + ".map"
    print("")
    print("GraspGuide %s report (%s)" % (env.subst("$PIOENV"), os.path.relpath(elf)))

    rows = parse_map(map_path) if os.path.isfile(map_path) else []
    if rows:
        flash, ram, _ = ownership(rows)
        tf, tr = sum(flash.values()), sum(ram.values())
        cats = sorted(set(flash) | set(ram), key=lambda c: -flash.get(c, 0))
        print("  %-28s %9s %7s %9s" % ("owner", "flash B", "%", "RAM B"))
        for c in cats:
            print("  %-28s %9d %6.1f%% %9d" % (c, flash[c], 100.0 * flash[c] / tf, ram[c]))
        core_f = flash["core (graspguide)"] + flash["core (Eigen)"]
        core_r = ram["core (graspguide)"] + ram["core (Eigen)"]
        print("  %-28s %9d %6.1f%% %9d" % ("total", tf, 100.0, tr))
        print(
            "  core share (graspguide + Eigen): %d B flash (%.1f%%), %d B static RAM "
            "(the core's state lives inside the Application object)"
            % (core_f, 100.0 * core_f / tf, core_r)
        )

    nm = _run(env, "nm", "-S", "--size-sort", elf)
    symbols, ram_syms = {}, []
    for line in nm.split("\n"):
        parts = line.split()
        if len(parts) == 4:
            symbols[parts[3]] = int(parts[1], 16)
            if parts[2] in "bBdD":
                ram_syms.append((int(parts[1], 16), parts[3]))
    dem = _demangle([s for _, s in ram_syms])
    biggest = sorted(ram_syms, reverse=True)[:4]
    print(
        "  largest RAM objects: "
        + ", ".join("%s %d B" % (_short(dem.get(s, s), 60), n) for n, s in biggest)
    )
    stack_reserve = None
    for line in _run(env, "nm", elf).split("\n"):
        if line.endswith(" _min_stack_size"):
            stack_reserve = int(line.split()[0], 16)

    callers, callees, prologue = call_graph(env, elf)
    print("  runtime helpers:")
    for line in helper_report(callers, symbols):
        print(line)

    frames, edges, dynamic, virtuals = parse_callgraph_info(build_dir)
    if not frames:
        print("  stack: no -fcallgraph-info=su output found")
        return
    # Eigen's blocked Householder code runs only for 48 or more reflectors: linked
    # (the size test is at run time) but dead for the core's sizes (at most 12).
    blocked = re.compile(r"apply_block_householder_on_the_left")
    for title, skip in (
        ("every linked path", None),
        ("without Eigen's blocked Householder path (dead here)", blocked),
    ):
        (depth, path), notes = worst_stack(
            "Reset_Handler", frames, edges, virtuals, callees, prologue, skip
        )
        dem = _demangle(path)
        dyn = [p for p in path if p in dynamic]
        print(
            "  worst-case stack, %s: %d B%s (reserved %s B)"
            % (
                title,
                depth,
                " + bounded allocas in %d frame(s)" % len(dyn) if dyn else "",
                stack_reserve if stack_reserve is not None else "?",
            )
        )
        print(
            "      "
            + " -> ".join(
                "%s[%d]" % (_short(dem.get(p, p), 40), frames.get(p, prologue.get(p, 0)))
                for p in path[2:]
            )
        )
        extra = sorted(
            n.split(":", 1)[1] for n in notes if n.startswith(("unknown:", "recursion:"))
        )
        if extra:
            print("      not counted (no frame info or recursive): " + ", ".join(extra[:8]))
        if stack_reserve is not None and depth > stack_reserve:
            print("  WARNING: worst-case stack exceeds the reserved stack")
    print(
        "      (+ up to 104 B per nested exception with FP context, + handler frames;"
        " allocas are bounded by EIGEN_STACK_ALLOCATION_LIMIT each)"
    )


report_alias = env.Alias(
    "m4freport", env["PIOMAINPROG"], env.VerboseAction(report, "Report for $SOURCE")
)
AlwaysBuild(report_alias)  # noqa: F821
env.Depends(report_alias, env.Alias("memreport"))  # after the builder's flash/RAM lines
Default(report_alias)  # noqa: F821
