"""Estimate Cortex-M4 cycles (STM32F407 at 168 MHz) from QEMU's execution log.

QEMU does not model time: under `-icount shift=0` its clock counts
instructions. This module turns the instructions of a QEMU log
(`-d in_asm,exec,nochain,int`) into an estimate of the cycles a Cortex-M4F
would spend on them, from the published instruction timings, plus a simple
model of the STM32F4 flash interface. It is an estimate: every assumption is
listed here, and docs/cycle-model.md says how it was checked.

Sources
-------
[TRM]   ARM Cortex-M4 Technical Reference Manual (ARM DDI 0439B, r0p1),
        3.3.1 (Table 3-1, "Processor instruction set summary", its Cycles
        column) and 3.3.2 ("Load/store timings").
[FPU]   The same manual's FPU chapter: the FPU instruction table (cycles) and
        the note after it on results consumed by the next instruction.
[RM]    ST RM0090 (STM32F405/407 reference manual), the Flash interface
        chapter: "Relation between CPU clock frequency and Flash memory read
        time" (5 wait states from 150 to 168 MHz at 2.7-3.6 V) and "Adaptive
        real-time memory accelerator (ART Accelerator)".
[IRQ]   The Cortex-M4's published exception timings (zero wait states): 12
        cycles from an exception to its handler's first instruction, 10 back,
        6 between handlers when tail-chaining.

Core timings (zero wait states) [TRM 3.3.1]
-------------------------------------------
* Data processing, moves, shifts, compares, bit fields, extends, saturation,
  the DSP and SIMD instructions, MSR/MRS, CPSID/CPSIE, NOP, DMB/DSB: 1.
* MUL, MLA, MLS, SMULL, UMULL, SMLAL, UMLAL, UMAAL and the DSP multiplies: 1.
* SDIV, UDIV: 2 to 12 (early termination on the operands, which the log does
  not show): the estimate charges 12; the `min` total charges 2.
* P, the pipeline refill, "ranges from 1 to 3": taken as 2 everywhere.
  B, BL, BX, BLX, MOV/ADD to PC: 1 + P = 3. A conditional branch (B<c>,
  CBZ, CBNZ, or any PC write inside an IT block) costs 1 when not taken and
  its full cost when taken; taken means the next block QEMU executes does not
  start at the instruction after it. TBB, TBH: 2 + P = 4.
  ISB: 1 + B with B at least P: 3.
* IT: 1. The TRM notes an IT can fold onto a preceding 16-bit instruction for
  0 cycles; folding is not modelled (pessimistic by at most 1 per IT).
  Conditional instructions inside an IT block are charged in full whether
  their condition passed or not (QEMU's log does not say; a PC write is the
  exception, see above).
* LDR, LDRB, LDRH, LDRSB, LDRSH, LDREX, STREX: 2; to PC: 2 + P.
  STR, STRB, STRH with an immediate offset (or none): 1 ("STR Rx,[Ry,#imm] is
  always one cycle", [TRM 3.3.2]); with a register offset: 2.
  Pipelining [TRM 3.3.2]: a single load or store that follows a single load
  (LDR family, LDREX, STREX, VLDR.32) whose destination is not in its address
  costs one cycle less ("LDR R0,[R1]; LDR R1,[R2] - normally three cycles
  total"); nothing pipelines after a store.
  A load or store whose address register was written by the instruction just
  before it (a data-processing instruction: anything that writes a core
  register except a load) stalls one more cycle [TRM 3.3.2].
* LDRD, STRD: 1 + N = 3, not pipelined. LDM, STM, PUSH, POP: 1 + N (N
  registers), + P when loading PC.
* Unaligned accesses (+1 or +2) are not modelled: the log has no addresses.
* The bus: SRAM and CCM accesses have no wait state; peripheral (APB/AHB)
  accesses are charged as memory (their bus wait states are not modelled).

FPU timings [FPU]
-----------------
* VADD, VSUB, VMUL, VNMUL, VABS, VNEG, VCMP, VCMPE, VCVT, VMOV (immediate,
  register, core<->single), VMRS, VMSR: 1. VMOV of two core registers
  (to or from a D register or two S registers): 2.
* VMLA, VMLS, VNMLA, VNMLS, VFMA, VFMS, VFNMA, VFNMS: 3.
* VDIV, VSQRT: 14 (charged in full: the integer instructions that may run
  alongside on hardware are not overlapped).
* VLDR.32 and VSTR.32: 2 (a VLDR.32 pipelines like an LDR); VLDR.64,
  VSTR.64: 3. VLDM, VSTM, VPUSH, VPOP: 1 + N single registers, 1 + 2N double.
* A result of VADD, VSUB, VMUL, VNMUL, VCVT, VDIV, VSQRT or a
  multiply-accumulate consumed by the very next instruction costs one more
  cycle, except when it is only the addend of a following multiply-accumulate
  (forwarded).

Exceptions [IRQ]
----------------
Entry 12 cycles (charged to the handler's first instruction), return 10
(charged to the handler's last), a return straight into another handler
(tail-chaining) 6 instead of 10 + 12. QEMU's `-d int` lines mark entries
("...loaded new PC") and returns ("Exception return: magic PC"). Late arrival,
lazy FPU stacking and the stacking of the FP context are not modelled.

Flash and the ART accelerator [RM]
----------------------------------
Code and constants are in flash (0x0800_0000, and its alias at 0): 5 wait
states at 168 MHz, so a read that the accelerator does not serve costs 5
cycles more. The accelerator reads 128-bit lines (16 bytes), modelled as:
* an instruction cache of 64 lines, least recently used replaced;
* a prefetch buffer holding the line after the last one fetched (prefetch
  on); a fetch from that line costs no wait. This is optimistic: on the
  board a prefetched line is ready 6 cycles after its read starts, so a
  line of 32-bit instructions run in fewer cycles still waits a little;
* a data cache of 8 lines, least recently used replaced, for the
  PC-relative loads (literal pools), whose address the log gives.
Every line the instructions of a block touch is one fetch, in order; a miss
costs 5 cycles charged to the first instruction in that line. Loads through a
register from flash (tables, string constants) are charged no wait state, as
if the data cache always held them: optimistic, since the log has no data
addresses. RAM (0x2000_0000 SRAM, 0x1000_0000 CCM) has no wait state.

How a log is read
-----------------
QEMU logs a block's instructions once, when it translates it ("IN:"), and
each execution ("Trace N: HOSTPTR [.../PC/.../CFLAGS]"). Each execution is
charged to its own translation, keyed by host pointer; an execution QEMU
abandoned part-way is followed by a block forced to an instruction count
(CFLAGS & 0x1ff) that starts inside it, and only the instructions before that
start ran; "Stopped execution of TB chain before" a block means it did not
run. An execution's cycles are settled when the next one is known (to see
whether its last branch was taken).
"""

import collections
import re

P = 2                 # pipeline refill, taken within the TRM's 1..3
DIV_MAX, DIV_MIN = 12, 2
FP_DIV = 14
FLASH_WAIT = 5        # RM0090 Table 10: 168 MHz, 2.7-3.6 V
LINE_SHIFT = 4        # 128-bit ART lines
ICACHE_LINES = 64
DCACHE_LINES = 8
EXC_ENTRY, EXC_RETURN, TAIL_CHAIN = 12, 10, 6
CLOCK_HZ = 168_000_000

CONDS = frozenset('eq ne cs hs cc lo mi pl vs vc hi ls ge lt gt le al'.split())

# Mnemonics as Capstone (QEMU's disassembler) prints them, without the
# condition, width (.w/.n) or data type (.f32) suffix.
_S = 'adc add and asr bic eor lsl lsr mov mul mvn neg orn orr ror rrx rsb sbc sub'.split()
ALU = set(_S) | {m + 's' for m in _S} | set(
    'adr addw subw movw movt cmp cmn tst teq clz rbit rev rev16 revsh bfc bfi sbfx ubfx '
    'sxtb sxth uxtb uxth sxtab sxtah uxtab uxtah sxtb16 uxtb16 sxtab16 uxtab16 '
    'ssat usat ssat16 usat16 sel pkhbt pkhtb nop yield sev mrs msr cpsid cpsie dmb dsb clrex '
    'qadd qsub qdadd qdsub qadd8 qadd16 qsub8 qsub16 qasx qsax '
    'sadd8 sadd16 ssub8 ssub16 sasx ssax uadd8 uadd16 usub8 usub16 uasx usax '
    'shadd8 shadd16 shsub8 shsub16 shasx shsax uhadd8 uhadd16 uhsub8 uhsub16 uhasx uhsax '
    'uqadd8 uqadd16 uqsub8 uqsub16 uqasx uqsax usad8 usada8 '
    'bkpt svc wfi wfe udf'.split())
MUL = set(
    'mla mls smull umull smlal umlal umaal smulbb smulbt smultb smultt smulwb smulwt '
    'smlabb smlabt smlatb smlatt smlawb smlawt smlalbb smlalbt smlaltb smlaltt '
    'smlad smladx smlald smlaldx smlsd smlsdx smlsld smlsldx smmul smmulr smmla smmlar '
    'smmls smmlsr smuad smuadx smusd smusdx'.split())
LONG_MUL = set('smull umull smlal umlal umaal smlalbb smlalbt smlaltb smlaltt smlald smlaldx '
               'smlsld smlsldx'.split())
DIV = {'sdiv', 'udiv'}
LOAD = set('ldr ldrb ldrh ldrsb ldrsh ldrt ldrbt ldrht ldrsbt ldrsht ldrex ldrexb ldrexh'.split())
STORE = set('str strb strh strt strbt strht'.split())
STREX = {'strex', 'strexb', 'strexh'}
LDM = set('ldm ldmia ldmfd ldmdb ldmea pop'.split())
STM = set('stm stmia stmea stmdb stmfd push'.split())
BRANCH = set('b bl blx bx cbz cbnz tbb tbh'.split())
IT = re.compile(r'^it[te]{0,3}$')
NOCORE_DEST = set('cmp cmn tst teq nop yield sev msr cpsid cpsie dmb dsb isb clrex bkpt svc wfi wfe udf'.split())
FP1 = set('vabs vneg vcmp vcmpe vmrs vmsr'.split())
FP_LAT2 = set('vadd vsub vmul vnmul vcvt vcvtr vcvtb vcvtt'.split())
FP_MAC = set('vmla vmls vnmla vnmls vfma vfms vfnma vfnms'.split())
FP_DIVS = {'vdiv', 'vsqrt'}
VLDM = set('vldm vldmia vldmdb vpop'.split())
VSTM = set('vstm vstmia vstmdb vpush'.split())
FP_ALL = FP1 | FP_LAT2 | FP_MAC | FP_DIVS | VLDM | VSTM | {'vmov', 'vldr', 'vstr'}
KNOWN = ALU | MUL | DIV | LOAD | STORE | STREX | LDM | STM | BRANCH | FP_ALL | {
    'isb', 'ldrd', 'strd'}

REG_NAMES = {'sb': 9, 'sl': 10, 'fp': 11, 'ip': 12, 'sp': 13, 'lr': 14, 'pc': 15}
CORE_RE = re.compile(r'\b(r1[0-5]|r[0-9]|sb|sl|fp|ip|sp|lr|pc)\b')
FP_RE = re.compile(r'\b([sd])([0-9]+)\b')
LINE_RE = re.compile(rb'^0x([0-9a-f]{8}):\s+([0-9a-f]{4})(?: ([0-9a-f]{4}))?\s+(\S+)\s*(.*?)\s*$')
PCREL_RE = re.compile(r'\[pc(?:, #(-?)(0x[0-9a-f]+|[0-9]+))?\]')
LIST_RE = re.compile(r'\{([^}]*)\}')


def core_reg(name):
    return REG_NAMES[name] if name in REG_NAMES else int(name[1:])


def core_regs(text):
    return frozenset(core_reg(m) for m in CORE_RE.findall(text))


def fp_regs(text):
    """S register numbers named in `text` (a D register is two)."""
    out = set()
    for kind, n in FP_RE.findall(text):
        n = int(n)
        out.update((2 * n, 2 * n + 1) if kind == 'd' else (n,))
    return frozenset(out)


def split_operands(ops):
    """Top-level comma-separated operands (brackets and braces kept whole)."""
    out, depth, cur = [], 0, ''
    for ch in ops:
        if ch in '[{':
            depth += 1
        elif ch in ']}':
            depth -= 1
        if ch == ',' and depth == 0:
            out.append(cur.strip())
            cur = ''
        else:
            cur += ch
    if cur.strip():
        out.append(cur.strip())
    return out


def reg_list_count(ops):
    """Registers in a {list} (ranges such as r4-r7 expanded), and whether PC is one."""
    m = LIST_RE.search(ops)
    if not m:
        return 0, False, 0
    n, pc, doubles = 0, False, 0
    for item in m.group(1).split(','):
        item = item.strip()
        if '-' in item:
            a, b = item.split('-')
            k = int(b.strip()[1:]) - int(a.strip()[1:]) + 1
            if a.strip()[0] == 'd':
                doubles += k
        else:
            k = 1
            if item == 'pc':
                pc = True
            if re.fullmatch(r'd[0-9]+', item):
                doubles += 1
        n += k
    return n, pc, doubles


def split_mnemonic(m):
    """(base, condition or None, data type) of a Capstone mnemonic."""
    m = m.lower()
    dt = ''
    if m.startswith('v') and '.' in m:
        m, _, dt = m.partition('.')
    for suffix in ('.w', '.n'):
        if m.endswith(suffix):
            m = m[:-2]
    if '.' in m:
        m, _, dt = m.partition('.')
    if m in KNOWN or IT.match(m):
        return m, None, dt
    if len(m) > 2 and m[-2:] in CONDS and m[:-2] in KNOWN:
        return m[:-2], m[-2:], dt
    return m, None, dt


def in_flash(addr):
    return 0x0800_0000 <= addr < 0x0810_0000 or addr < 0x0010_0000


class Insn:
    """One instruction of a translated block, with its static timing."""

    __slots__ = ('addr', 'size', 'text', 'base', 'cost', 'cost_min', 'taken_extra', 'cond_pcw',
                 'pcw', 'kind', 'mem', 'store_imm', 'ld_dest', 'addr_regs', 'dp_dest', 'fp_dest',
                 'fp_src', 'fp_acc', 'fp_mac', 'lit', 'known', 'div')

    def __init__(self, addr, size, mnemonic, ops):
        self.addr, self.size = addr, size
        self.text = (mnemonic + ' ' + ops).strip()
        base, cond, dt = split_mnemonic(mnemonic)
        self.base = base
        self.known = base in KNOWN or bool(IT.match(base))
        self.cost = 1
        self.cost_min = None
        self.taken_extra = 0
        self.pcw = False          # writes the PC (ends a block)
        self.cond_pcw = False     # ... only if its condition passes
        self.kind = 'other'       # 'ld' (single load: pipelines the next), 'st', 'multi', 'br'
        self.mem = False          # a load or store (address stall applies)
        self.store_imm = False
        self.ld_dest = frozenset()
        self.addr_regs = frozenset()
        self.dp_dest = frozenset()
        self.fp_dest = frozenset()    # written by an FP op whose result has a latency of 2
        self.fp_src = frozenset()
        self.fp_acc = frozenset()
        self.fp_mac = False
        self.lit = None               # flash address of a PC-relative load
        self.div = False
        opl = split_operands(ops)
        first = opl[0] if opl else ''
        bracket = ops[ops.find('['):] if '[' in ops else ''

        if base in BRANCH or (base in ALU and first == 'pc' and base not in ('cmp', 'cmn', 'tst', 'teq')):
            self.pcw, self.kind = True, 'br'
            if base in ('tbb', 'tbh'):
                self.cost = 2 + P
                self.mem = True
                self.addr_regs = core_regs(bracket)
            elif base in ('cbz', 'cbnz') or (base == 'b' and cond):
                self.cond_pcw, self.cost, self.taken_extra = True, 1, P
            else:
                self.cost = 1 + P
                if cond:   # a PC write inside an IT block
                    self.cond_pcw, self.cost, self.taken_extra = True, 1, P
        elif IT.match(base):
            self.cost = 1
        elif base in LOAD or base in STREX:
            self.mem = True
            self.addr_regs = core_regs(bracket.split(']')[0]) | (
                core_regs(bracket.split(']', 1)[1]) if ']' in bracket else frozenset())
            dest = core_regs(first)
            if 15 in dest and base in LOAD:
                self.pcw, self.kind, self.cost = True, 'br', 2 + P
                if cond:
                    self.cond_pcw, self.cost, self.taken_extra = True, 1, 1 + P
            else:
                self.kind, self.cost, self.ld_dest = 'ld', 2, dest
            self._literal(ops)
        elif base in STORE:
            self.mem, self.kind = True, 'st'
            inside = bracket.split(']')[0]
            post = bracket.split(']', 1)[1] if ']' in bracket else ''
            self.addr_regs = core_regs(inside) | core_regs(post)
            reg_offset = len(CORE_RE.findall(inside)) > 1
            self.store_imm = not reg_offset
            self.cost = 1 if self.store_imm else 2
        elif base in ('ldrd', 'strd'):
            self.mem, self.kind, self.cost = True, 'multi', 3
            self.addr_regs = core_regs(bracket)
            if base == 'ldrd':
                self._literal(ops)
        elif base in LDM or base in STM:
            n, pc, _ = reg_list_count(ops)
            self.mem, self.kind, self.cost = True, 'multi', 1 + n
            self.addr_regs = frozenset([13]) if base in ('push', 'pop') else core_regs(first)
            if pc and base in LDM:
                self.pcw, self.kind = True, 'br'
                self.cost = 1 + n + P
                if cond:
                    self.cond_pcw, self.cost, self.taken_extra = True, 1, n + P
        elif base in DIV:
            self.cost, self.cost_min, self.div = DIV_MAX, DIV_MIN, True
            self.dp_dest = core_regs(first)
        elif base in MUL or base in ('mul', 'muls'):
            self.dp_dest = core_regs(','.join(opl[:2])) if base in LONG_MUL else core_regs(first)
        elif base == 'isb':
            self.cost = 1 + P
        elif base in ('vldr', 'vstr'):
            self.mem = True
            self.addr_regs = core_regs(bracket)
            double = first.startswith('d')
            if base == 'vldr':
                self.kind = 'multi' if double else 'ld'
                self._literal(ops)
            else:
                self.kind = 'multi' if double else 'st'
                self.fp_src = fp_regs(first)
            self.cost = 3 if double else 2
        elif base in VLDM or base in VSTM:
            n, _, doubles = reg_list_count(ops)
            self.mem, self.kind = True, 'multi'
            self.cost = 1 + n + doubles
            self.addr_regs = frozenset([13]) if base in ('vpush', 'vpop') else core_regs(first)
            if base in VSTM:
                self.fp_src = fp_regs(LIST_RE.search(ops).group(1)) if LIST_RE.search(ops) else frozenset()
        elif base == 'vmov':
            cores = CORE_RE.findall(ops)
            self.cost = 2 if len(cores) == 2 else 1
            if first and (first[0] == 'r' or first in REG_NAMES):
                self.dp_dest = core_regs(','.join(opl[:len(cores)]))
                self.fp_src = fp_regs(ops)
            else:
                self.fp_src = fp_regs(','.join(opl[1:]))
        elif base in FP1:
            if base in ('vcmp', 'vcmpe'):
                self.fp_src = fp_regs(ops)
            elif base == 'vmrs':
                if first != 'apsr_nzcv':
                    self.dp_dest = core_regs(first)
            elif base != 'vmsr':
                self.fp_src = fp_regs(','.join(opl[1:]))
        elif base in FP_LAT2 or base in FP_MAC or base in FP_DIVS:
            dest = fp_regs(first)
            self.fp_dest = dest
            self.fp_src = fp_regs(','.join(opl[1:]))
            if base in FP_MAC:
                self.cost, self.fp_mac, self.fp_acc = 3, True, dest
                self.fp_src = self.fp_src | dest
            elif base in FP_DIVS:
                self.cost = FP_DIV
        # Anything else (ALU, extends, DSP, system, unknown): 1 cycle.
        if not self.dp_dest and not self.mem and not self.pcw and base not in NOCORE_DEST \
                and not base.startswith('v') and not IT.match(base) and first:
            self.dp_dest = core_regs(first)
        if self.cost_min is None:
            self.cost_min = self.cost

    def _literal(self, ops):
        m = PCREL_RE.search(ops)
        if m:
            off = int(m.group(2), 0) if m.group(2) else 0
            self.lit = ((self.addr + 4) & ~3) + (-off if m.group(1) else off)

    def pair(self, prev):
        """Cycles this instruction costs more (or less) after `prev` [TRM 3.3.2, FPU]."""
        d = 0
        if self.mem:
            if prev.dp_dest and prev.dp_dest & self.addr_regs:
                d += 1
            elif prev.kind == 'ld' and self.kind in ('ld', 'st') and not self.store_imm \
                    and not (prev.ld_dest & self.addr_regs):
                d -= 1
        if prev.fp_dest and prev.fp_dest & self.fp_src:
            used = prev.fp_dest & self.fp_src
            if not (self.fp_mac and used <= self.fp_acc and not (used & (self.fp_src - self.fp_acc))):
                d += 1
        return d


_insn_cache = {}


def parse_line(line):
    """An Insn from an in_asm line (bytes), or None if the line is not an instruction."""
    ins = _insn_cache.get(line)
    if ins is None:
        m = LINE_RE.match(line)
        if not m:
            return None
        size = 4 if m.group(3) else 2
        ins = Insn(int(m.group(1), 16), size, m.group(4).decode(), m.group(5).decode())
        _insn_cache[line] = ins
    return ins


class Static:
    """What does not change between executions of one translation run to `n` instructions."""

    __slots__ = ('n', 'cycles', 'cycles_min', 'divs', 'costs', 'lines', 'lits', 'first', 'last')

    def __init__(self, insns, n):
        run = insns[:n]
        self.n = n
        costs = []
        prev = None
        for ins in run:
            c = ins.cost + (ins.pair(prev) if prev is not None else 0)
            costs.append(c)
            prev = ins
        self.costs = costs
        self.cycles = sum(costs)
        self.cycles_min = self.cycles - sum(i.cost - i.cost_min for i in run)
        self.divs = sum(1 for i in run if i.div)
        lines = []
        for ins in run:
            if not in_flash(ins.addr):
                continue
            for line in (ins.addr >> LINE_SHIFT, (ins.addr + ins.size - 1) >> LINE_SHIFT):
                if not lines or lines[-1][1] != line:
                    lines.append((ins.addr, line))
        self.lines = lines
        self.lits = [(i.addr, i.lit >> LINE_SHIFT) for i in run if i.lit is not None and in_flash(i.lit)]
        self.first = run[0] if run else None
        self.last = run[-1] if run else None


class Tally:
    """Cycles charged to one part of a profile (the main line, interrupts, one run)."""

    def __init__(self):
        self.execs = collections.Counter()   # (translation key, instructions run) -> executions
        self.extra = collections.Counter()   # address -> dynamic cycles (branches, waits, stalls)
        self.flash = 0                       # flash wait cycles (in extra)
        self.exc = 0                         # exception entry and return cycles (in extra)

    def totals(self, model):
        """(instructions, cycles, cycles with 2-cycle divides, divides, flash waits)."""
        instr = cycles = cmin = divs = 0
        for (key, n), k in self.execs.items():
            if k == 0 or n == 0:
                continue
            s = model.static(key, n)
            instr += k * n
            cycles += k * s.cycles
            cmin += k * s.cycles_min
            divs += k * s.divs
        dyn = sum(self.extra.values())
        return instr, cycles + dyn, cmin + dyn, divs, self.flash

    def per_address(self, model, instr, cycles):
        """Add this tally's instructions and cycles per address to two Counters."""
        for (key, n), k in self.execs.items():
            if k == 0 or n == 0:
                continue
            s = model.static(key, n)
            for ins, c in zip(model.tbs[key], s.costs):
                instr[ins.addr] += k
                cycles[ins.addr] += k * c
        for a, c in self.extra.items():
            cycles[a] += c


class _Adder:
    """A counter that keeps nothing: `self[k] += v` hands (k, v) to a function."""

    def __init__(self, add):
        self._add = add

    def __getitem__(self, key):
        return 0

    def __setitem__(self, key, value):
        self._add(key, value)


class Clock:
    """A sink like a Tally that keeps only a running total of estimated
    cycles and instructions, as blocks are settled: the time so far, for
    the gaps between events (a block is settled when the next one starts,
    so the clock trails by at most one block)."""

    def __init__(self, model):
        self.cycles = 0
        self.instr = 0
        self.flash = 0
        self.exc = 0

        def execs(key, count):
            k, n = key
            self.cycles += count * model.static(k, n).cycles
            self.instr += count * n

        def extra(_addr, cycles):
            self.cycles += cycles

        self.execs = _Adder(execs)
        self.extra = _Adder(extra)


class Model:
    """Follows a QEMU log's block executions and charges their cycles to Tallies."""

    def __init__(self):
        self.tbs = {}                 # translation key (host pointer, generation) -> [Insn]
        self._gen = {}
        self._current = {}            # host pointer -> its translation key
        self._static = {}
        self.icache = collections.OrderedDict()
        self.dcache = collections.OrderedDict()
        self.prefetched = None
        self.pending = None           # [key, pc, n, sinks]: the last execution, not settled
        self.stack = []               # executions interrupted by an exception
        self.resume = None            # the interrupted execution to settle at the next block
        self.returned = None          # (sinks, address) of a handler that just returned
        self.entry_cost = 0
        self.just_returned = False
        self.last = None              # the last instruction settled (for pairing)
        # Charged executions cut short, and stopped before they ran.
        self.cut = self.stopped_n = 0
        self.entries = self.returns = self.tail_chains = 0
        self.unknown = collections.Counter()

    def translated(self, ptr, insns):
        """A translation ("IN:" block) now at host pointer `ptr` (QEMU may reuse one)."""
        g = self._gen.get(ptr, -1) + 1
        self._gen[ptr] = g
        key = (ptr, g)
        self._current[ptr] = key
        self.tbs[key] = insns
        for ins in insns:
            if not ins.known:
                self.unknown[ins.base] += 1
        return key

    def static(self, key, n):
        s = self._static.get((key, n))
        if s is None:
            s = self._static[(key, n)] = Static(self.tbs[key], n)
        return s

    def execute(self, ptr, pc, cflags, sinks):
        """A block execution ("Trace" line): settle the previous one, hold this one."""
        key = self._current.get(ptr)
        if key is None:
            key = self.translated(ptr, [Insn(pc, 2, '?', '')])
        self.just_returned = False
        prior = self.resume if self.resume is not None else self.pending
        if prior is not None and cflags & 0x1ff:
            insns = self.tbs[prior[0]]
            for i, ins in enumerate(insns[:prior[2]]):
                if ins.addr == pc:
                    prior[2] = i
                    if prior[3]:
                        self.cut += 1
                    break
        if self.resume is not None:
            self._settle(self.resume, pc)
            self.resume = None
        if self.returned is not None:
            sinks_r, addr = self.returned
            self._charge_exc(sinks_r, addr, EXC_RETURN)
            self.returned = None
        if self.pending is not None:
            self._settle(self.pending, pc)
        self.pending = [key, pc, len(self.tbs[key]), sinks]
        if self.entry_cost:
            first = self.tbs[key][0].addr
            self._charge_exc(sinks, first, self.entry_cost)
            self.entry_cost = 0

    def stopped(self, ptr):
        """"Stopped execution of TB chain before" ptr: the held execution did not run."""
        if self.pending is not None and self.pending[0] == self._current.get(ptr):
            if self.pending[3]:
                self.stopped_n += 1
            self.pending = None

    def exception_entry(self):
        self.entries += 1
        if self.just_returned:
            # Tail-chaining: the previous handler's return and this entry.
            self.just_returned = False
            self.tail_chains += 1
            self.returned = None
            self.stack.append(self.resume)
            self.resume = None
            self.entry_cost = TAIL_CHAIN
        else:
            self.stack.append(self.pending)
            self.pending = None
            self.entry_cost = EXC_ENTRY
        self.last = None

    def exception_return(self):
        self.returns += 1
        if self.pending is not None:
            ins = self.tbs[self.pending[0]]
            n = self.pending[2]
            self._settle(self.pending, None, taken=True)
            self.returned = (self.pending[3], ins[n - 1].addr if n else ins[0].addr)
            self.pending = None
        self.resume = self.stack.pop() if self.stack else None
        self.just_returned = True
        self.last = None

    def finish(self):
        if self.resume is not None:
            self._settle(self.resume, None)
            self.resume = None
        if self.returned is not None:
            self._charge_exc(*self.returned, EXC_RETURN)
            self.returned = None
        if self.pending is not None:
            self._settle(self.pending, None)
            self.pending = None

    def _charge_exc(self, sinks, addr, cycles):
        for s in sinks:
            s.extra[addr] += cycles
            s.exc += cycles

    def _fetch(self, cache, line, size, prefetch):
        if line in cache:
            cache.move_to_end(line)
            wait = 0
        else:
            wait = 0 if prefetch and line == self.prefetched else FLASH_WAIT
            cache[line] = True
            if len(cache) > size:
                cache.popitem(last=False)
        if prefetch:
            nxt = line + 1
            self.prefetched = None if nxt in cache else nxt
        return wait

    def _settle(self, ex, next_pc, taken=None):
        key, _, n, sinks = ex
        if n == 0:
            return
        s = self.static(key, n)
        extra = []
        flash = 0
        if self.last is not None:
            d = s.first.pair(self.last)
            if d:
                extra.append((s.first.addr, d))
        for addr, line in s.lines:
            w = self._fetch(self.icache, line, ICACHE_LINES, True)
            if w:
                extra.append((addr, w))
                flash += w
        for addr, line in s.lits:
            w = self._fetch(self.dcache, line, DCACHE_LINES, False)
            if w:
                extra.append((addr, w))
                flash += w
        last = s.last
        if last.cond_pcw:
            if taken is None:
                taken = next_pc is not None and next_pc != last.addr + last.size
            if taken:
                extra.append((last.addr, last.taken_extra))
        self.last = last
        for t in sinks:
            t.execs[(key, n)] += 1
            for a, c in extra:
                t.extra[a] += c
            t.flash += flash


def scan(log, choose, model=None):
    """Feed a QEMU log (`-d in_asm,exec,nochain,int`) to a Model.

    choose(pc, depth) is called for every block execution, in order, with
    the number of exception handlers being run, and returns the Tallies to
    charge it to (possibly none).
    """
    model = model or Model()
    tr = re.compile(rb'^Trace \d+: (0x[0-9a-f]+) \[[0-9a-f]+/([0-9a-f]+)/[0-9a-f]+/([0-9a-f]+)\]')
    stopped = re.compile(rb'^Stopped execution of TB chain before (0x[0-9a-f]+)')
    pending = None    # the instructions of the last IN: block, waiting for its host pointer
    cur = None
    depth = 0
    with open(log, 'rb') as f:
        for line in f:
            if line.startswith(b'Trace'):
                if cur:
                    pending = cur
                cur = None
                m = tr.match(line)
                if not m:
                    continue
                key, pc, cflags = m.group(1), int(m.group(2), 16), int(m.group(3), 16)
                if pending is not None:
                    model.translated(key, pending)
                    pending = None
                model.execute(key, pc, cflags, choose(pc, depth))
            elif line.startswith(b'IN:'):
                cur = []
            elif cur is not None:
                ins = parse_line(line)
                if ins is not None:
                    cur.append(ins)
                elif not line.strip() or line.startswith(b'---'):
                    if cur:
                        pending = cur
                    cur = None
            elif line.startswith(b'Stopped execution'):
                m = stopped.match(line)
                if m:
                    model.stopped(m.group(1))
            elif line.startswith(b'...loaded new PC'):
                depth += 1
                model.exception_entry()
            elif line.startswith(b'Exception return: magic PC'):
                depth = max(0, depth - 1)
                model.exception_return()
    model.finish()
    return model
