//! Stack high-water mark: the free stack is painted with a pattern at boot
//! and [`peak`] finds the deepest word that no longer holds it.

/// The pattern painted below the stack pointer.
const PAINT: u32 = 0xCAFE_F00D;

unsafe extern "C" {
    /// The lowest address of the stack (cortex-m-rt's link.x; flip-link
    /// moves it to the start of RAM).
    static mut _stack_end: u32;
    /// The highest address of the stack (exclusive).
    static mut _stack_start: u32;
}

fn bounds() -> (*mut u32, *mut u32) {
    // Only the symbols' addresses are taken.
    (core::ptr::addr_of_mut!(_stack_end), core::ptr::addr_of_mut!(_stack_start))
}

/// Bytes of stack in all.
pub fn size() -> usize {
    let (bottom, top) = bounds();
    top as usize - bottom as usize
}

/// Paint the unused stack, up to 256 bytes below the current stack
/// pointer. Call once, early in `main`.
pub fn paint() {
    let (bottom, _) = bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let end = sp.saturating_sub(256) & !3;
    let mut p = bottom;
    while (p as usize) < end {
        // SAFETY: between the stack's lowest address and well below the
        // live part of the stack: memory nothing else uses.
        unsafe {
            p.write_volatile(PAINT);
            p = p.add(1);
        }
    }
}

/// The most stack used since [`paint`], in bytes (from the top of the
/// stack down to the deepest word overwritten).
pub fn peak() -> usize {
    let (bottom, top) = bounds();
    let mut p = bottom;
    // SAFETY: reads of the stack region between its bounds.
    while p < top && unsafe { p.read_volatile() } == PAINT {
        p = unsafe { p.add(1) };
    }
    top as usize - p as usize
}
