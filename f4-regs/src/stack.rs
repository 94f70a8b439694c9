//! The stack's high-water mark: cortex-m-rt (feature `paint-stack`) paints the stack's whole
//! region, from `_stack_end` (just above the statics) up to `_stack_start`, with
//! `0xCCCC_CCCC` before `main`; the stack grows down, so the painted words left at the bottom
//! are what it never reached.

/// cortex-m-rt's paint (`STACK_PAINT_VALUE`).
pub const PAINT: u32 = 0xCCCC_CCCC;

/// The bytes at the bottom of the stack's region `[bottom, top)` that the stack has never
/// reached: painted words counted up from `bottom` (volatile reads) until the first that is
/// not.
///
/// # Safety
///
/// `bottom..top` must be readable, word-aligned memory (the stack's region).
pub unsafe fn unused_bytes(bottom: *const u32, top: *const u32) -> usize {
    let mut p = bottom;
    let mut n = 0usize;
    while p < top {
        // SAFETY: within [bottom, top), readable by the caller's promise.
        if unsafe { core::ptr::read_volatile(p) } != PAINT {
            break;
        }
        n += 4;
        // SAFETY: stays within or one past the region.
        p = unsafe { p.add(1) };
    }
    n
}
