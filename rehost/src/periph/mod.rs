//! The chip's peripherals at their addresses (RM0090 §2.3 Table 1, RM0390 §2.2.2 Table 1),
//! each a register model of its own; everything else in the peripheral space reads back what
//! was written (GPIO, SYSCFG, EXTI, the other timers, …), which is all the firmware asks of
//! them.

pub mod adc;
pub mod clock;
pub mod dma;
pub mod flash;
pub mod iwdg;
pub mod otg;
pub mod tim;
pub mod usart;
pub mod usb_host;

use std::collections::HashMap;

/// Base addresses.
pub mod base {
    /// TIM2 (the encoder).
    pub const TIM2: u32 = 0x4000_0000;
    /// TIM4 (embassy's time driver).
    pub const TIM4: u32 = 0x4000_0800;
    /// USART2 (the Nucleo's link).
    pub const USART2: u32 = 0x4000_4400;
    /// IWDG.
    pub const IWDG: u32 = 0x4000_3000;
    /// PWR.
    pub const PWR: u32 = 0x4000_7000;
    /// TIM8 (the bridge's PWM).
    pub const TIM8: u32 = 0x4001_0400;
    /// ADC1 (and the common registers at +0x300).
    pub const ADC1: u32 = 0x4001_2000;
    /// GPIOC (the bridge's pins).
    pub const GPIOC: u32 = 0x4002_0800;
    /// RCC.
    pub const RCC: u32 = 0x4002_3800;
    /// The flash interface.
    pub const FLASH: u32 = 0x4002_3C00;
    /// DMA1.
    pub const DMA1: u32 = 0x4002_6000;
    /// DMA2.
    pub const DMA2: u32 = 0x4002_6400;
    /// USB OTG FS (the F405's link), on the AHB2 (RM0090 §2.3 Table 1).
    pub const OTG_FS: u32 = 0x5000_0000;
}

/// Interrupt numbers (RM0090 Table 61, RM0390 Table 38).
pub mod irq {
    /// DMA1 stream 5 (USART2 RX).
    pub const DMA1_STREAM5: usize = 16;
    /// DMA1 stream 6 (USART2 TX).
    pub const DMA1_STREAM6: usize = 17;
    /// ADC1-3.
    pub const ADC: usize = 18;
    /// TIM2.
    pub const TIM2: usize = 28;
    /// TIM4.
    pub const TIM4: usize = 30;
    /// USART2.
    pub const USART2: usize = 38;
    /// TIM8 update (and TIM13).
    pub const TIM8_UP_TIM13: usize = 44;
    /// TIM8 capture/compare.
    pub const TIM8_CC: usize = 46;
    /// DMA1 stream 0-4 and 7 are 11-15 and 47; DMA2 stream 0.
    pub const DMA2_STREAM0: usize = 56;
    /// USB OTG FS global interrupt (RM0090 Table 61: position 67, 0x0000_014C).
    pub const OTG_FS: usize = 67;
}

/// The peripherals.
#[derive(Debug, Clone)]
pub struct Periphs {
    /// RCC.
    pub rcc: clock::Rcc,
    /// PWR.
    pub pwr: clock::Pwr,
    /// The flash interface.
    pub flash: flash::FlashIf,
    /// The watchdog.
    pub iwdg: iwdg::Iwdg,
    /// TIM8.
    pub tim8: tim::Timer,
    /// TIM4.
    pub tim4: tim::Timer,
    /// TIM2's registers (its counter is the encoder's: the machine serves CNT).
    pub tim2: tim::Timer,
    /// ADC1.
    pub adc: adc::Adc,
    /// DMA1.
    pub dma1: dma::Dma,
    /// DMA2.
    pub dma2: dma::Dma,
    /// USART2.
    pub usart2: usart::Usart,
    /// USB OTG FS in device mode.
    pub otg: otg::OtgFs,
    /// The host at the other end of the USB cable (kept over the chip's resets: the PC
    /// stays; it sees the device let go of D+ and enumerates it again).
    pub usb_host: usb_host::Host,
    /// Every other register, read back as written.
    pub plain: HashMap<u32, u32>,
}

impl Periphs {
    /// The peripherals at a power-on reset, on a part with `flash_size` bytes of flash and a
    /// core at `hz`.
    pub fn new(flash_size: u32, hz: u64) -> Periphs {
        Periphs {
            rcc: clock::Rcc::new(),
            pwr: clock::Pwr::default(),
            flash: flash::FlashIf::new(flash_size),
            iwdg: iwdg::Iwdg::new(hz),
            tim8: tim::Timer::new(1, 16, true),
            tim4: tim::Timer::new(2, 16, false),
            tim2: tim::Timer::new(2, 32, false),
            adc: adc::Adc::new(2),
            dma1: dma::Dma::default(),
            dma2: dma::Dma::default(),
            usart2: usart::Usart::new(4),
            otg: otg::OtgFs::new(),
            usb_host: usb_host::Host::default(),
            plain: HashMap::new(),
        }
    }

    /// The interrupt lines asserted now.
    pub fn irq_lines(&self) -> Vec<usize> {
        let mut v = Vec::new();
        if self.tim8.irq_update() {
            v.push(irq::TIM8_UP_TIM13);
        }
        if self.tim4.irq() {
            v.push(irq::TIM4);
        }
        if self.adc.irq() {
            v.push(irq::ADC);
        }
        if self.dma2.streams[0].irq() {
            v.push(irq::DMA2_STREAM0);
        }
        if self.dma1.streams[5].irq() {
            v.push(irq::DMA1_STREAM5);
        }
        if self.dma1.streams[6].irq() {
            v.push(irq::DMA1_STREAM6);
        }
        if self.usart2.irq() {
            v.push(irq::USART2);
        }
        if self.otg.irq() {
            v.push(irq::OTG_FS);
        }
        v
    }
}
