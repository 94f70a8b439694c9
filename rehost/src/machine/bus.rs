//! The peripheral space as the core sees it (RM0090 §2.3, the memory map: APB1, APB2, AHB1
//! from 0x4000_0000): reads and writes dispatched to the register models (`crate::periph`) at
//! the core's time, with what a write starts (a DMA stream, a flash program or erase, a
//! reset request); and the FP registers by number.

use unicorn_engine::RegisterARM as R;

use super::*;

pub(super) fn reg_s(k: usize) -> R {
    const S: [R; 16] = [
        R::S0,
        R::S1,
        R::S2,
        R::S3,
        R::S4,
        R::S5,
        R::S6,
        R::S7,
        R::S8,
        R::S9,
        R::S10,
        R::S11,
        R::S12,
        R::S13,
        R::S14,
        R::S15,
    ];
    S[k]
}

/// A read of the peripheral space.
pub(super) fn periph_read(uc: &mut Unicorn<'_, Chip>, addr: u32, size: usize) -> u32 {
    let c = uc.get_data_mut();
    let now = c.cycles;
    let word = addr & !3;
    let off = |b: u32| word - b;
    let v = match word {
        a if (base::TIM2..base::TIM2 + 0x400).contains(&a) => {
            if off(base::TIM2) == 0x24 {
                (c.enc_counts as u32).wrapping_add(c.enc_offset)
            } else {
                c.p.tim2.read(off(base::TIM2), now)
            }
        }
        a if (base::TIM4..base::TIM4 + 0x400).contains(&a) => c.p.tim4.read(off(base::TIM4), now),
        a if (base::USART2..base::USART2 + 0x400).contains(&a) => {
            if off(base::USART2) == 0x04 && c.p.usart2.dma_rx() {
                c.dr_reads_under_dma += 1;
            }
            c.p.usart2.read(off(base::USART2))
        }
        a if (base::IWDG..base::IWDG + 0x400).contains(&a) => c.p.iwdg.read(off(base::IWDG)),
        a if (base::PWR..base::PWR + 0x400).contains(&a) => c.p.pwr.read(off(base::PWR)),
        a if (base::TIM8..base::TIM8 + 0x400).contains(&a) => {
            let v = c.p.tim8.read(off(base::TIM8), now);
            // Events the read's catch-up fired: handled at once (see the write's).
            if c.p.tim8.has_events() {
                c.stop_soon();
            }
            v
        }
        a if (base::ADC1..base::ADC1 + 0x400).contains(&a) => c.p.adc.read(off(base::ADC1)),
        a if (base::RCC..base::RCC + 0x400).contains(&a) => c.p.rcc.read(off(base::RCC)),
        a if (base::FLASH..base::FLASH + 0x400).contains(&a) => c.p.flash.read(off(base::FLASH)),
        a if (base::DMA1..base::DMA1 + 0x400).contains(&a) => c.p.dma1.read(off(base::DMA1)),
        a if (base::DMA2..base::DMA2 + 0x400).contains(&a) => c.p.dma2.read(off(base::DMA2)),
        _ => c.p.plain.get(&word).copied().unwrap_or(0),
    };
    let shift = (addr & 3) * 8;
    let v = v >> shift;
    match size {
        1 => v & 0xFF,
        2 => v & 0xFFFF,
        _ => v,
    }
}

/// A write to the peripheral space.
pub(super) fn periph_write(uc: &mut Unicorn<'_, Chip>, addr: u32, size: usize, value: u32) {
    let word = addr & !3;
    let shift = (addr & 3) * 8;
    // Sub-word writes merge into the register's current value (the F4's peripherals take
    // byte and halfword writes on most registers).
    let value = if size < 4 {
        let old = periph_read(uc, word, 4);
        let mask = if size == 1 { 0xFF } else { 0xFFFF } << shift;
        (old & !mask) | ((value << shift) & mask)
    } else {
        value
    };
    let mut erase = None;
    {
        let c = uc.get_data_mut();
        let now = c.cycles;
        let off = |b: u32| word - b;
        let mut stop = false;
        match word {
            a if (base::TIM2..base::TIM2 + 0x400).contains(&a) => {
                if off(base::TIM2) == 0x24 {
                    c.enc_offset = value.wrapping_sub(c.enc_counts as u32);
                } else {
                    c.p.tim2.write(off(base::TIM2), value, now);
                }
            }
            a if (base::TIM4..base::TIM4 + 0x400).contains(&a) => {
                c.p.tim4.write(off(base::TIM4), value, now);
                stop = true;
            }
            a if (base::USART2..base::USART2 + 0x400).contains(&a) => {
                c.p.usart2.write(off(base::USART2), value, now);
                stop = true;
            }
            a if (base::IWDG..base::IWDG + 0x400).contains(&a) => {
                c.p.iwdg.write(off(base::IWDG), value, now)
            }
            a if (base::PWR..base::PWR + 0x400).contains(&a) => {
                c.p.pwr.write(off(base::PWR), value)
            }
            a if (base::TIM8..base::TIM8 + 0x400).contains(&a) => {
                let o = off(base::TIM8);
                c.p.tim8.write(o, value, now);
                // The compare values need no stop; the counter's set-up does, and so do the
                // events the write's catch-up fired (an ADC trigger due inside this run):
                // handled at once, at their own times.
                stop = !(0x34..=0x40).contains(&o) || c.p.tim8.has_events();
            }
            a if (base::ADC1..base::ADC1 + 0x400).contains(&a) => {
                c.p.adc.write(off(base::ADC1), value, now);
                stop = true;
            }
            a if (base::RCC..base::RCC + 0x400).contains(&a) => {
                c.p.rcc.write(off(base::RCC), value)
            }
            a if (base::FLASH..base::FLASH + 0x400).contains(&a) => {
                erase = c.p.flash.write(off(base::FLASH), value);
            }
            a if (base::DMA1..base::DMA1 + 0x400).contains(&a) => {
                c.p.dma1.write(off(base::DMA1), value);
                stop = true;
            }
            a if (base::DMA2..base::DMA2 + 0x400).contains(&a) => {
                c.p.dma2.write(off(base::DMA2), value);
                stop = true;
            }
            _ => {
                c.p.plain.insert(word, value);
            }
        }
        if stop {
            c.stop_soon();
        }
    }
    if let Some(e) = erase {
        // The supply failing mid-erase: the sector's first half erased.
        let c = uc.get_data_mut();
        if c.inject.power_lost {
            return;
        }
        let len = if c.inject.flash_write_cut() {
            c.stop_soon();
            e.len / 2
        } else {
            e.len
        };
        let _ = uc.mem_write(e.addr as u64, &vec![0xFF; len as usize]);
    }
}
