//! TIM2 as the quadrature encoder's counter (embassy's `Qei` sets the encoder mode and the
//! pins).

use crate::pac;

/// The counter's full 32-bit range (ARR = 2³² − 1) and the digital filter `filter` (the
/// IC1F/IC2F code, RM0090 §18.4.7, from gms-core's `drive::encoder_filter`) on both inputs
/// (embassy's `Qei` leaves them at 0, no filter: a glitch the filter does not reject is a
/// count lost for good). Written with the counter running: the filter only delays edges by
/// its window.
pub fn range_and_filter(tim: pac::timer::TimGp32, filter: u8) {
    tim.arr().write_value(u32::MAX);
    tim.ccmr_input(0).modify(|w| {
        let f = pac::timer::vals::FilterValue::from_bits(filter);
        w.set_icf(0, f);
        w.set_icf(1, f);
    });
}
