//! Small hand-written loops whose Cortex-M4 cycle counts follow exactly from
//! the Cortex-M4 Technical Reference Manual (ARM DDI 0439B: Table 3-1, 3.3.2
//! and the FPU's instruction table), to check `scripts/cm4_cycles.py`: run
//! under QEMU with the profiler's trace flags by `scripts/cycle-model-check`,
//! which compares the model's estimate for each loop with the figure written
//! beside it.
//!
//! Each loop is a naked function (its instructions are exactly the ones
//! below) and runs twice: the check measures the second run, from its first
//! instruction to its return, with the flash accelerator's caches warm, so
//! no flash wait state enters the expected figures. The figures use the
//! model's choices where the TRM gives a range: a pipeline refill P of 2, a
//! divide at its worst, 12.
//!
//! Most loops share one frame: `movs r0, #20` (1 cycle), the body, `subs`
//! (1) and `bne` (1 + P = 3 when taken, 1 the last time), `bx lr` (3): with
//! N = 20 iterations the frame is 42 instructions and 4N + 2 = 82 cycles.
//!
//! Build and run: `scripts/cycle-model-check`.
#![no_std]
#![no_main]

use core::arch::naked_asm;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use panic_probe as _;
// The device's interrupt vectors (cortex-m-rt needs them to link).
use stm32f4xx_hal as _;

/// Scratch words the loads and stores use (in SRAM: no wait state).
static mut CYC_BUF: [u32; 16] = [0; 16];

/// Four 16-bit ADDs. Body 4 cycles: 82 + 20 x 4.
/// Expected: 122 instructions, 162 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_alu() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "adds r1, r1, #1",
        "adds r2, r2, #1",
        "adds r3, r3, #1",
        "adds r1, r1, #1",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// Eight 32-bit data-processing instructions (MOVW, MOVT, shift, BFI, CLZ,
/// RBIT, UXTB, SSAT), 1 cycle each: 82 + 20 x 8.
/// Expected: 202 instructions, 242 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_alu_wide() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "movw r2, #0x1234",
        "movt r2, #0x5678",
        "lsl.w r3, r2, #3",
        "bfi r3, r2, #4, #8",
        "clz r3, r2",
        "rbit r3, r2",
        "uxtb.w r3, r2",
        "ssat r3, #16, r2",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// A pointer chase: each LDR's address is the previous LDR's result, so none
/// pipelines (2 cycles each). Set-up: MOVW, MOVT, then STR whose base the
/// MOVT just wrote (1 + 1 address stall): 4. 82 + 4 + 20 x 8.
/// Expected: 125 instructions, 246 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_ldr_dependent() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "str r1, [r1]",
        "movs r0, #20",
        "2:",
        "ldr r1, [r1]",
        "ldr r1, [r1]",
        "ldr r1, [r1]",
        "ldr r1, [r1]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// Four independent LDRs: 2 + 1 + 1 + 1 ("LDR R0,[R1,R5]; LDR R1,[R2];
/// LDR R2,[R3,#4] - normally four cycles total", TRM 3.3.2).
/// 82 + 2 + 20 x 5.
/// Expected: 124 instructions, 184 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_ldr_pipelined() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "ldr r2, [r1]",
        "ldr r3, [r1, #4]",
        "ldr r2, [r1, #8]",
        "ldr r3, [r1, #12]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// LDR then a register-offset STR that pipelines after it (2 + 1), twice:
/// nothing pipelines after a store, so the second LDR costs 2 again.
/// 82 + 3 + 20 x 6.
/// Expected: 125 instructions, 205 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_ldr_str() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r3, #4",
        "movs r0, #20",
        "2:",
        "ldr r2, [r1]",
        "str r2, [r1, r3]",
        "ldr r2, [r1, #8]",
        "str r2, [r1, r3]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// Immediate-offset stores: "STR Rx,[Ry,#imm] is always one cycle"
/// (TRM 3.3.2), STRH and STRB alike. 82 + 2 + 20 x 4.
/// Expected: 124 instructions, 164 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_str_imm() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "str r2, [r1]",
        "str r2, [r1, #4]",
        "strh r2, [r1, #8]",
        "strb r2, [r1, #12]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// Register-offset stores, none after a load: 2 cycles each.
/// 82 + 3 + 20 x 8.
/// Expected: 125 instructions, 245 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_str_reg() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r3, #4",
        "movs r0, #20",
        "2:",
        "str r2, [r1, r3]",
        "str r2, [r1, r3]",
        "str r2, [r1, r3]",
        "str r2, [r1, r3]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// A load whose base the instruction before it wrote: "stalls the pipeline
/// for an additional cycle" (TRM 3.3.2): ADDS 1 + LDR 2 + 1, twice.
/// 82 + 2 + 20 x 8.
/// Expected: 124 instructions, 244 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_agu_stall() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "adds r1, r1, #0",
        "ldr r2, [r1]",
        "adds r1, r1, #0",
        "ldr r2, [r1]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// LDRD and STRD: 1 + N = 3 each, not pipelined. 82 + 2 + 20 x 6.
/// Expected: 84 instructions, 204 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_ldrd_strd() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "ldrd r2, r3, [r1]",
        "strd r2, r3, [r1, #8]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// LDM and STM of 4 registers: 1 + N = 5 each. Set-up PUSH of 2 (3),
/// MOVW, MOVT (2); POP of 2 (3) before the return. 82 + 5 + 3 + 20 x 10.
/// Expected: 86 instructions, 290 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_ldm_stm4() {
    naked_asm!(
        "push {{r4, r5}}",
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "ldm r1, {{r2, r3, r4, r5}}",
        "stm r1, {{r2, r3, r4, r5}}",
        "subs r0, r0, #1",
        "bne 2b",
        "pop {{r4, r5}}",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// LDM and STM of 8 registers: 1 + N = 9 each. Set-up PUSH of 6 (7), MOVW,
/// MOVT (2); POP of 6 (7). 82 + 9 + 7 + 20 x 18.
/// Expected: 86 instructions, 458 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_ldm_stm8() {
    naked_asm!(
        "push {{r4, r5, r6, r7, r8, r9}}",
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "ldm r1, {{r2, r3, r4, r5, r6, r7, r8, r9}}",
        "stm r1, {{r2, r3, r4, r5, r6, r7, r8, r9}}",
        "subs r0, r0, #1",
        "bne 2b",
        "pop {{r4, r5, r6, r7, r8, r9}}",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// SDIV, 2 to 12 cycles by its operands (100 / 7 on hardware ends early;
/// QEMU's log does not show operands, so the model charges the worst, 12).
/// 82 + 2 + 20 x 24.
/// Expected: 84 instructions, 564 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_sdiv() {
    naked_asm!(
        "movs r3, #100",
        "movs r2, #7",
        "movs r0, #20",
        "2:",
        "sdiv r1, r3, r2",
        "sdiv r1, r3, r2",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// UDIV, as SDIV: 12 each. 82 + 2 + 20 x 24.
/// Expected: 84 instructions, 564 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_udiv() {
    naked_asm!(
        "movs r3, #100",
        "movs r2, #7",
        "movs r0, #20",
        "2:",
        "udiv r1, r3, r2",
        "udiv r1, r3, r2",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// MUL, MLA, MLS, SMULBB: 1 cycle each on the Cortex-M4. 82 + 2 + 20 x 4.
/// Expected: 124 instructions, 164 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_mul_mla() {
    naked_asm!(
        "movs r2, #3",
        "movs r3, #5",
        "movs r0, #20",
        "2:",
        "mul r1, r2, r3",
        "mla r1, r2, r3, r1",
        "mls r1, r2, r3, r1",
        "smulbb r1, r2, r3",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// SMULL, UMULL, SMLAL, UMLAL: 1 cycle each on the Cortex-M4. 82 + 20 x 4.
/// Expected: 122 instructions, 162 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_long_mul() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "smull r1, r2, r3, r12",
        "umull r1, r2, r3, r12",
        "smlal r1, r2, r3, r12",
        "umlal r1, r2, r3, r12",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// VADD, VMUL, VSUB, VCVT with no result used by the next instruction:
/// 1 cycle each. 82 + 20 x 4.
/// Expected: 122 instructions, 162 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_fp_independent() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "vadd.f32 s0, s1, s2",
        "vmul.f32 s3, s4, s5",
        "vsub.f32 s6, s7, s8",
        "vcvt.s32.f32 s9, s10",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// Each result consumed by the next instruction, one cycle more (the FPU):
/// VADD 1, VADD 2, VMUL 2, VMOV to a core register 2. 82 + 20 x 7.
/// Expected: 122 instructions, 222 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_fp_dependent() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "vadd.f32 s0, s0, s1",
        "vadd.f32 s0, s0, s1",
        "vmul.f32 s0, s0, s1",
        "vmov r1, s0",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// VMLA and VFMA, 3 cycles each; a chain through the accumulator only is
/// forwarded (no extra cycle). 82 + 20 x 12.
/// Expected: 122 instructions, 322 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_fp_mac() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "vmla.f32 s0, s1, s2",
        "vmla.f32 s0, s3, s4",
        "vfma.f32 s5, s6, s7",
        "vfma.f32 s5, s6, s7",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// VDIV and VSQRT: 14 cycles each. 82 + 20 x 28.
/// Expected: 82 instructions, 642 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_fp_div_sqrt() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "vdiv.f32 s0, s1, s2",
        "vsqrt.f32 s3, s4",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// VLDR and VSTR (single precision, 2 cycles), pipelined like LDR: VLDR 2,
/// VLDR 1, VSTR 1 (after a load), VSTR 2 (after a store). 82 + 2 + 20 x 6.
/// Expected: 124 instructions, 204 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_fp_load_store() {
    naked_asm!(
        "movw r1, :lower16:{buf}",
        "movt r1, :upper16:{buf}",
        "movs r0, #20",
        "2:",
        "vldr s0, [r1]",
        "vldr s1, [r1, #4]",
        "vstr s0, [r1, #8]",
        "vstr s1, [r1, #12]",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        buf = sym CYC_BUF,
    );
}

/// VPUSH and VPOP of two double registers: 1 + 2N = 5 each. 82 + 20 x 10.
/// Expected: 82 instructions, 282 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_vpush_vpop() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "vpush {{d8, d9}}",
        "vpop {{d8, d9}}",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// A call and return: BL 3, BX LR 3 (1 + P each). The frame returns by
/// POP {r4, pc} (1 + 2 + P = 5) instead of BX LR, after PUSH {r4, lr} (3):
/// 82 - 3 + 5 + 3 + 20 x 6.
/// Expected: 83 instructions, 207 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_call_return() {
    naked_asm!(
        "push {{r4, lr}}",
        "movs r0, #20",
        "2:",
        "bl 7f",
        "subs r0, r0, #1",
        "bne 2b",
        "pop {{r4, pc}}",
        "7:",
        "bx lr",
    );
}

/// Conditional branches not taken: 1 cycle each. 82 + 20 x 4.
/// Expected: 122 instructions, 162 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_branch_not_taken() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "cmp r0, #100",
        "beq 8f",
        "cmp r0, #101",
        "beq 8f",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        "8:",
        "b 8b",
    );
}

/// Conditional branches taken over a NOP (which does not run): CMP 1,
/// BNE 1 + P = 3, twice. 82 + 20 x 8.
/// Expected: 122 instructions, 242 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_branch_taken() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "cmp r0, #0",
        "bne 5f",
        "nop",
        "5:",
        "cmp r0, #0",
        "bne 6f",
        "nop",
        "6:",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// CBNZ taken (1 + P = 3) over a NOP, CBZ not taken (1). 82 + 20 x 4.
/// Expected: 82 instructions, 162 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_cbz_cbnz() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "cbnz r0, 5f",
        "nop",
        "5:",
        "cbz r0, 9f",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        "9:",
        "b 9b",
    );
}

/// An IT block: CMP, ITE (1: folding is not modelled), and both conditional
/// MOVs charged whether or not their condition holds. 82 + 20 x 4.
/// Expected: 122 instructions, 162 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_it_block() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "cmp r0, #10",
        "ite hi",
        "movhi r2, #1",
        "movls r2, #2",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// PC-relative loads from a literal in flash: LDR 2, LDR 1 (pipelined), the
/// accelerator's data cache warm. 82 + 20 x 3.
/// Expected: 82 instructions, 142 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_literal() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "ldr r2, 8f",
        "ldr r3, 8f",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
        ".p2align 2",
        "8:",
        ".word 0x12345678",
    );
}

/// TBB to the instruction after its one-entry table: 2 + P = 4.
/// Set-up MOVS 1. 82 + 1 + 20 x 4.
/// Expected: 63 instructions, 163 cycles.
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_table_branch() {
    naked_asm!(
        "movs r2, #0",
        "movs r0, #20",
        "2:",
        "tbb [pc, r2]",
        "3:",
        ".byte (4f - 3b) / 2",
        ".byte 0",
        "4:",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// Barriers: DMB 1, DSB 1 (1 + B, B at least 0), ISB 3 (1 + B, B at least
/// P). 82 + 20 x 5.
/// Expected: 102 instructions, 182 cycles.
#[rustfmt::skip] // one instruction a line, like the others
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_barriers() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "dmb sy",
        "dsb sy",
        "isb sy",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// An exception and its return: SVC 1, entry 12, the handler's BX LR 3,
/// return 10. 82 + 20 x 26.
/// Expected: 82 instructions, 602 cycles.
#[rustfmt::skip] // one instruction a line, like the others
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn cyc_svc() {
    naked_asm!(
        "movs r0, #20",
        "2:",
        "svc #0",
        "subs r0, r0, #1",
        "bne 2b",
        "bx lr",
    );
}

/// The SVCall handler `cyc_svc` takes (in place of cortex-m-rt's default).
#[allow(non_snake_case)]
#[unsafe(naked)]
#[unsafe(no_mangle)]
extern "C" fn SVCall() {
    naked_asm!("bx lr");
}

/// The loops, in the order they run.
static LOOPS: [extern "C" fn(); 30] = [
    cyc_alu,
    cyc_alu_wide,
    cyc_ldr_dependent,
    cyc_ldr_pipelined,
    cyc_ldr_str,
    cyc_str_imm,
    cyc_str_reg,
    cyc_agu_stall,
    cyc_ldrd_strd,
    cyc_ldm_stm4,
    cyc_ldm_stm8,
    cyc_sdiv,
    cyc_udiv,
    cyc_mul_mla,
    cyc_long_mul,
    cyc_fp_independent,
    cyc_fp_dependent,
    cyc_fp_mac,
    cyc_fp_div_sqrt,
    cyc_fp_load_store,
    cyc_vpush_vpop,
    cyc_call_return,
    cyc_branch_not_taken,
    cyc_branch_taken,
    cyc_cbz_cbnz,
    cyc_it_block,
    cyc_literal,
    cyc_table_branch,
    cyc_barriers,
    cyc_svc,
];

#[entry]
fn main() -> ! {
    for f in LOOPS {
        // Once to fill the accelerator's caches, once to measure.
        f();
        f();
    }
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}
