//! USB OTG FS in device mode, as the F405's link uses it (RM0090 §34; offsets from
//! 0x5000_0000, §34.16.1): the core and device registers embassy-usb-synopsys-otg 0.3.3 and
//! embassy-stm32 0.6's glue touch, the shared receive FIFO of status entries and data words
//! (§34.11.1, popped through GRXSTSP and read through the FIFO window at 0x1000), one transmit
//! FIFO per IN endpoint (§34.11.2, pushed at 0x1000·(n+1)), the interrupt hierarchy (§34.15:
//! DIEPINT/DOEPINT → DAINT → GINTSTS, a level line gated by GAHBCFG.GINT), and the core's
//! side of each transaction a host starts (§34.17.6: SETUP, OUT, IN, the bus reset and the
//! enumeration's end). The host is [`super::usb_host`].
//!
//! What the driver depends on and the model therefore does: GRSTCTL.AHBIDL reads 1 and the
//! FIFO flush bits clear themselves at once; GINTSTS.CMOD reads 0 (device); CID reads 0x1200
//! (the F405's OTG FS, §34.16.2); DSTS.ENUMSPD reads 3 (full speed on the internal PHY) after
//! the enumeration; EP0's USBAEP reads 1 (§34.16.4 "always active"); CNAK, SNAK, SD0PID and
//! SODDFRM act and read 0, their effect the endpoint's NAK status (NAKSTS); a SETUP clears
//! EP0's STALL both ways (§34.16.4 DIEPCTL0/DOEPCTL0 STALL); an OUT endpoint takes a packet
//! while its NAK is clear and sets it after each one (the driver re-arms with CNAK only);
//! DIEPINT.TXFE is the FIFO at least half empty (GAHBCFG.TXFELVL 0) and reaches DAINT only
//! through DIEPEMPMSK; DTXFSTS is the free room in words.
//!
//! Not modelled: the host mode, the OTG protocol (SRP/HNP), VBUS sensing (the firmware sets
//! NOVBUSSENS), SOF and the frame number, isochronous endpoints, the DMA, suspend's clock
//! gating (PCGCCTL stores), the data toggle (a host that sees the same packet twice is not
//! modelled).

use std::collections::{HashMap, VecDeque};

/// Endpoints each way (the F405's OTG FS: 4, RM0090 §34.3.1).
pub const EPS: usize = 4;

/// GINTSTS bits (RM0090 §34.16.2 OTG_FS_GINTSTS).
pub mod gint {
    /// Current mode (0: device).
    pub const CMOD: u32 = 1 << 0;
    /// OTG interrupt.
    pub const OTGINT: u32 = 1 << 2;
    /// Receive FIFO non-empty.
    pub const RXFLVL: u32 = 1 << 4;
    /// USB suspend.
    pub const USBSUSP: u32 = 1 << 11;
    /// USB reset.
    pub const USBRST: u32 = 1 << 12;
    /// Enumeration done.
    pub const ENUMDNE: u32 = 1 << 13;
    /// IN endpoint interrupt.
    pub const IEPINT: u32 = 1 << 18;
    /// OUT endpoint interrupt.
    pub const OEPINT: u32 = 1 << 19;
    /// Resume/remote wake-up detected.
    pub const WKUPINT: u32 = 1 << 31;
    /// The bits the application clears by writing 1 (the rest are read-only or derived).
    pub const W1C: u32 = 0xF030_FC0A;
}

/// DIEPCTL/DOEPCTL bits (RM0090 §34.16.4).
mod epctl {
    pub const USBAEP: u32 = 1 << 15;
    pub const NAKSTS: u32 = 1 << 17;
    pub const STALL: u32 = 1 << 21;
    pub const CNAK: u32 = 1 << 26;
    pub const SNAK: u32 = 1 << 27;
    pub const EPDIS: u32 = 1 << 30;
    pub const EPENA: u32 = 1 << 31;
    /// Bits that act and read 0: CNAK, SNAK, SD0PID, SODDFRM.
    pub const ACTIONS: u32 = 0xF << 26;
}

/// DIEPINT/DOEPINT bits.
mod epint {
    pub const XFRC: u32 = 1 << 0;
    pub const EPDISD: u32 = 1 << 1;
    pub const STUP: u32 = 1 << 3;
    pub const TXFE: u32 = 1 << 7;
}

/// GRXSTSP's packet status (RM0090 §34.16.2 OTG_FS_GRXSTSP, device mode).
mod pktsts {
    pub const OUT_DATA: u32 = 2;
    pub const OUT_DONE: u32 = 3;
    pub const SETUP_DONE: u32 = 4;
    pub const SETUP_DATA: u32 = 6;
}

/// What the device answered a token with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Handshake {
    /// Taken (OUT, SETUP), or data given (IN: the packet, possibly empty).
    Ack(Vec<u8>),
    /// Not now.
    Nak,
    /// Halted (or a request refused).
    Stall,
    /// No answer (the endpoint is not active): the host times out.
    Silent,
}

#[derive(Debug, Clone, Default)]
struct InEp {
    ctl: u32,
    nak: bool,
    int: u32,
    tsiz: u32,
    fifo: VecDeque<u32>,
}

#[derive(Debug, Clone, Default)]
struct OutEp {
    ctl: u32,
    nak: bool,
    int: u32,
    tsiz: u32,
}

/// One receive FIFO entry: its status word and its data words.
#[derive(Debug, Clone)]
struct RxEntry {
    status: u32,
    words: Vec<u32>,
}

/// The OTG FS core in device mode.
#[derive(Debug, Clone)]
pub struct OtgFs {
    gotgint: u32,
    gahbcfg: u32,
    gusbcfg: u32,
    /// GINTSTS's latched (write-1-to-clear) bits.
    gintsts: u32,
    gintmsk: u32,
    grxfsiz: u32,
    /// DIEPTXF0 (0x028) and DIEPTXF1-3 (0x104-0x10C).
    txf: [u32; EPS],
    gccfg: u32,
    cid: u32,
    dcfg: u32,
    dctl: u32,
    /// DSTS.ENUMSPD after the enumeration (0 before).
    enumspd: u32,
    diepmsk: u32,
    doepmsk: u32,
    daintmsk: u32,
    diepempmsk: u32,
    ins: [InEp; EPS],
    outs: [OutEp; EPS],
    rx: VecDeque<RxEntry>,
    /// The data words of the entry popped last, read through the FIFO window.
    cur: VecDeque<u32>,
    /// Registers the model gives no behaviour (read back as written).
    plain: HashMap<u32, u32>,
    /// The core's 48 MHz clock as the RCC makes it \[Hz\] (none: off), set by the machine.
    pub clk48_hz: Option<u64>,
}

impl Default for OtgFs {
    fn default() -> Self {
        Self::new()
    }
}

impl OtgFs {
    /// The core at reset (RM0090 §34.16.6's reset values where the driver reads them).
    pub fn new() -> OtgFs {
        let mut o = OtgFs {
            gotgint: 0,
            gahbcfg: 0,
            gusbcfg: 0x0000_0A00,
            gintsts: 0x0400_0020 & gint::W1C,
            gintmsk: 0,
            grxfsiz: 0x200,
            txf: [0x0200_0200; EPS],
            gccfg: 0,
            cid: 0x0000_1200,
            dcfg: 0x0220_0000,
            dctl: 0,
            enumspd: 0,
            diepmsk: 0,
            doepmsk: 0,
            daintmsk: 0,
            diepempmsk: 0,
            ins: Default::default(),
            outs: Default::default(),
            rx: VecDeque::new(),
            cur: VecDeque::new(),
            plain: HashMap::new(),
            clk48_hz: None,
        };
        for e in &mut o.outs {
            e.nak = true;
        }
        o
    }

    /// The D+ pull-up is on: the transceiver powered (GCCFG.PWRDWN), the soft disconnect off
    /// (DCTL.SDIS), VBUS taken as present (GCCFG.NOVBUSSENS) — RM0090 §34.5.2.
    pub fn pulled_up(&self) -> bool {
        self.gccfg & (1 << 16) != 0 && self.gccfg & (1 << 21) != 0 && self.dctl & 2 == 0
    }

    /// The full-speed signalling the host can read: the core's clock within USB 2.0's
    /// ±0.25 % of 48 MHz (§7.1.11: 12 Mb/s ±0.25 %); else why not.
    pub fn signalling(&self) -> Result<(), String> {
        match self.clk48_hz {
            Some(f) if f.abs_diff(48_000_000) <= 120_000 => Ok(()),
            Some(f) => Err(format!(
                "the OTG FS core's clock is {f} Hz, not 48 MHz ±0.25 %: the host reads no valid packet"
            )),
            None => Err("the OTG FS core has no 48 MHz clock (PLL off or OTGFSEN clear)".into()),
        }
    }

    /// The device address the application set (DCFG.DAD).
    pub fn address(&self) -> u8 {
        ((self.dcfg >> 4) & 0x7F) as u8
    }

    /// Whether IN endpoint `ep` (1-3) is active (set at SET_CONFIGURATION).
    pub fn in_active(&self, ep: usize) -> bool {
        ep == 0 || self.ins.get(ep).is_some_and(|e| e.ctl & epctl::USBAEP != 0)
    }

    /// The interrupt line (IRQ 67): GAHBCFG.GINT and an unmasked GINTSTS bit (a level).
    pub fn irq(&self) -> bool {
        self.gahbcfg & 1 != 0 && self.gintsts_now() & self.gintmsk != 0
    }

    fn ep0_mps(&self) -> usize {
        match self.ins[0].ctl & 3 {
            0 => 64,
            1 => 32,
            2 => 16,
            _ => 8,
        }
    }

    fn in_mps(&self, ep: usize) -> usize {
        if ep == 0 {
            self.ep0_mps()
        } else {
            (self.ins[ep].ctl & 0x7FF) as usize
        }
    }

    fn out_mps(&self, ep: usize) -> usize {
        if ep == 0 {
            self.ep0_mps()
        } else {
            (self.outs[ep].ctl & 0x7FF) as usize
        }
    }

    /// A transmit FIFO's depth \[words\].
    fn txf_depth(&self, ep: usize) -> usize {
        (self.txf[ep] >> 16) as usize
    }

    fn txfe(&self, ep: usize) -> bool {
        let depth = self.txf_depth(ep);
        depth.saturating_sub(self.ins[ep].fifo.len()) >= depth / 2
    }

    fn daint(&self) -> u32 {
        let mut v = 0;
        for n in 0..EPS {
            let empty = self.txfe(n) && self.diepempmsk & (1 << n) != 0;
            if self.ins[n].int & self.diepmsk != 0 || empty {
                v |= 1 << n;
            }
            if self.outs[n].int & self.doepmsk != 0 {
                v |= 1 << (16 + n);
            }
        }
        v
    }

    fn gintsts_now(&self) -> u32 {
        let mut v = self.gintsts;
        if self.gotgint != 0 {
            v |= gint::OTGINT;
        }
        if !self.rx.is_empty() {
            v |= gint::RXFLVL;
        }
        let d = self.daint() & self.daintmsk;
        if d & 0xFFFF != 0 {
            v |= gint::IEPINT;
        }
        if d >> 16 != 0 {
            v |= gint::OEPINT;
        }
        v
    }

    /// The receive FIFO's words in use (status entries and data).
    fn rx_words(&self) -> usize {
        self.rx.iter().map(|e| 1 + e.words.len()).sum::<usize>() + self.cur.len()
    }

    /// A register's value without a read's side effects (GRXSTSP's pop, the FIFO's).
    pub fn peek(&self, off: u32) -> u32 {
        match off {
            0x004 => self.gotgint,
            0x008 => self.gahbcfg,
            0x00C => self.gusbcfg,
            // AHBIDL: the AHB master idle; the flushes and the soft reset done at once.
            0x010 => 0x8000_0000,
            0x014 => self.gintsts_now(),
            0x018 => self.gintmsk,
            0x01C | 0x020 => self.rx.front().map_or(0, |e| e.status),
            0x024 => self.grxfsiz,
            0x028 => self.txf[0],
            0x038 => self.gccfg,
            0x03C => self.cid,
            0x104 | 0x108 | 0x10C => self.txf[((off - 0x100) / 4) as usize],
            0x800 => self.dcfg,
            0x804 => self.dctl,
            0x808 => self.enumspd << 1,
            0x810 => self.diepmsk,
            0x814 => self.doepmsk,
            0x818 => self.daint(),
            0x81C => self.daintmsk,
            0x834 => self.diepempmsk,
            0x900..=0x97F => {
                let n = ((off - 0x900) / 0x20) as usize;
                let e = &self.ins[n];
                match off & 0x1F {
                    0x00 => ep_ctl_read(e.ctl, e.nak, n),
                    0x08 => e.int | if self.txfe(n) { epint::TXFE } else { 0 },
                    0x10 => e.tsiz,
                    0x18 => (self.txf_depth(n).saturating_sub(e.fifo.len())) as u32,
                    _ => 0,
                }
            }
            0xB00..=0xB7F => {
                let n = ((off - 0xB00) / 0x20) as usize;
                let e = &self.outs[n];
                match off & 0x1F {
                    0x00 => ep_ctl_read(e.ctl, e.nak, n),
                    0x08 => e.int,
                    0x10 => e.tsiz,
                    _ => 0,
                }
            }
            0x1000.. => self.cur.front().copied().unwrap_or(0),
            _ => self.plain.get(&off).copied().unwrap_or(0),
        }
    }

    /// A word read at `off`: GRXSTSP pops the receive FIFO's head (its data words then read
    /// through the FIFO window; popping a SETUP's "done" entry raises DOEPINT0.STUP, RM0090
    /// §34.17.6 "Setup stages"), a read in the FIFO window pops a data word.
    pub fn read(&mut self, off: u32) -> u32 {
        match off {
            0x020 => {
                let Some(e) = self.rx.pop_front() else {
                    return 0;
                };
                self.cur = e.words.into_iter().collect();
                if (e.status >> 17) & 0xF == pktsts::SETUP_DONE {
                    self.outs[0].int |= epint::STUP;
                }
                e.status
            }
            0x1000..=0x1_FFFF => self.cur.pop_front().unwrap_or(0),
            _ => self.peek(off),
        }
    }

    /// A word written at `off`.
    pub fn write(&mut self, off: u32, v: u32) {
        match off {
            0x004 => self.gotgint &= !v,
            0x008 => self.gahbcfg = v,
            0x00C => self.gusbcfg = v,
            0x010 => {
                // RXFFLSH, TXFFLSH with TXFNUM (0x10: all): done at once (RM0090 §34.16.2).
                if v & (1 << 4) != 0 {
                    self.rx.clear();
                    self.cur.clear();
                }
                if v & (1 << 5) != 0 {
                    let n = ((v >> 6) & 0x1F) as usize;
                    for (i, e) in self.ins.iter_mut().enumerate() {
                        if n == 0x10 || n == i {
                            e.fifo.clear();
                        }
                    }
                }
                if v & 1 != 0 {
                    // CSRST: the core's state machines and FIFOs reset (not the registers the
                    // application configured, as the manual has it for the soft reset).
                    self.rx.clear();
                    self.cur.clear();
                    for e in &mut self.ins {
                        e.fifo.clear();
                    }
                }
            }
            0x014 => self.gintsts &= !(v & gint::W1C),
            0x018 => self.gintmsk = v,
            0x024 => self.grxfsiz = v,
            0x028 => self.txf[0] = v,
            0x038 => self.gccfg = v,
            0x03C => self.cid = v,
            0x104 | 0x108 | 0x10C => self.txf[((off - 0x100) / 4) as usize] = v,
            0x800 => self.dcfg = v,
            0x804 => self.dctl = v,
            0x810 => self.diepmsk = v,
            0x814 => self.doepmsk = v,
            0x81C => self.daintmsk = v,
            0x834 => self.diepempmsk = v,
            0x900..=0x97F => {
                let n = ((off - 0x900) / 0x20) as usize;
                match off & 0x1F {
                    0x00 => {
                        let e = &mut self.ins[n];
                        ep_ctl_write(&mut e.ctl, &mut e.nak, &mut e.int, v);
                    }
                    0x08 => self.ins[n].int &= !(v & !epint::TXFE),
                    0x10 => self.ins[n].tsiz = v,
                    _ => {}
                }
            }
            0xB00..=0xB7F => {
                let n = ((off - 0xB00) / 0x20) as usize;
                match off & 0x1F {
                    0x00 => {
                        let e = &mut self.outs[n];
                        ep_ctl_write(&mut e.ctl, &mut e.nak, &mut e.int, v);
                    }
                    0x08 => self.outs[n].int &= !v,
                    0x10 => self.outs[n].tsiz = v,
                    _ => {}
                }
            }
            0x1000..=0x1_FFFF => {
                // Transmit FIFO n at 0x1000·(n+1) (RM0090 §34.16.1); a push into a full FIFO
                // is lost (the driver checks DTXFSTS first).
                let n = (off / 0x1000 - 1) as usize;
                if n < EPS && self.ins[n].fifo.len() < self.txf_depth(n) {
                    self.ins[n].fifo.push_back(v);
                }
            }
            _ => {
                self.plain.insert(off, v);
            }
        }
    }

    /// The host drives the bus reset (RM0090 §34.17.5 "Endpoint initialization on USB
    /// reset"): USBRST latched, every endpoint's transfer and halt ended, NAK set on the OUT
    /// endpoints, endpoints 1-3 inactive, the enumeration speed not yet known.
    pub fn bus_reset(&mut self) {
        self.gintsts |= gint::USBRST;
        self.enumspd = 0;
        for (n, e) in self.ins.iter_mut().enumerate() {
            ep_reset(&mut e.ctl, &mut e.nak, n);
        }
        for (n, e) in self.outs.iter_mut().enumerate() {
            ep_reset(&mut e.ctl, &mut e.nak, n);
        }
    }

    /// The reset over: the enumeration done at full speed (DSTS.ENUMSPD 3, ENUMDNE).
    pub fn enumeration_done(&mut self) {
        self.enumspd = 3;
        self.gintsts |= gint::ENUMDNE;
    }

    /// The host suspends the bus (3 ms idle): USBSUSP; or resumes it: WKUPINT.
    pub fn suspend(&mut self, suspended: bool) {
        self.gintsts |= if suspended {
            gint::USBSUSP
        } else {
            gint::WKUPINT
        };
    }

    /// A SETUP packet to endpoint 0: always taken (RM0090 §34.17.6 "SETUP transactions"),
    /// EP0's STALL cleared both ways, the OUT side NAKing until the application re-arms it,
    /// STUPCNT counted down; the FIFO gets the SETUP data entry then the "done" entry.
    pub fn setup(&mut self, packet: [u8; 8]) -> Handshake {
        if self.rx_words() + 4 > self.rx_depth() {
            // No room: the core does not answer (the host retries).
            return Handshake::Silent;
        }
        self.ins[0].ctl &= !epctl::STALL;
        self.outs[0].ctl &= !(epctl::STALL | epctl::EPENA);
        self.outs[0].nak = true;
        let stupcnt = (self.outs[0].tsiz >> 29) & 3;
        self.outs[0].tsiz = (self.outs[0].tsiz & !(3 << 29)) | (stupcnt.saturating_sub(1) << 29);
        let w0 = u32::from_le_bytes([packet[0], packet[1], packet[2], packet[3]]);
        let w1 = u32::from_le_bytes([packet[4], packet[5], packet[6], packet[7]]);
        self.rx.push_back(RxEntry {
            status: (pktsts::SETUP_DATA << 17) | (8 << 4),
            words: vec![w0, w1],
        });
        self.rx.push_back(RxEntry {
            status: pktsts::SETUP_DONE << 17,
            words: Vec::new(),
        });
        Handshake::Ack(Vec::new())
    }

    fn rx_depth(&self) -> usize {
        (self.grxfsiz & 0xFFFF) as usize
    }

    /// An OUT data packet to endpoint `ep` (RM0090 §34.17.6 "OUT data transfers"): taken
    /// while the endpoint's NAK is clear and the receive FIFO has room, then NAK set until
    /// the application clears it (the driver's re-arm); the FIFO gets the data entry and the
    /// "transfer completed" entry, DOEPINT.XFRC set, the transfer size counted down.
    pub fn out(&mut self, ep: usize, data: &[u8]) -> Handshake {
        let Some(e) = self.outs.get(ep) else {
            return Handshake::Silent;
        };
        if ep > 0 && e.ctl & epctl::USBAEP == 0 {
            return Handshake::Silent;
        }
        if e.ctl & epctl::STALL != 0 {
            return Handshake::Stall;
        }
        if data.len() > self.out_mps(ep) {
            // Babble: the core drops it (the host sees no handshake).
            return Handshake::Silent;
        }
        let words = data.len().div_ceil(4);
        if self.outs[ep].nak || self.rx_words() + 2 + words > self.rx_depth() {
            return Handshake::Nak;
        }
        let w: Vec<u32> = data
            .chunks(4)
            .map(|c| {
                let mut b = [0u8; 4];
                b[..c.len()].copy_from_slice(c);
                u32::from_le_bytes(b)
            })
            .collect();
        let n = ep as u32;
        self.rx.push_back(RxEntry {
            status: (pktsts::OUT_DATA << 17) | ((data.len() as u32) << 4) | n,
            words: w,
        });
        self.rx.push_back(RxEntry {
            status: (pktsts::OUT_DONE << 17) | n,
            words: Vec::new(),
        });
        let e = &mut self.outs[ep];
        let size = (e.tsiz & 0x7_FFFF).saturating_sub(data.len() as u32);
        let pkts = ((e.tsiz >> 19) & 0x3FF).saturating_sub(1);
        e.tsiz = (e.tsiz & 0xE000_0000) | (pkts << 19) | size;
        e.ctl &= !epctl::EPENA;
        e.int |= epint::XFRC;
        e.nak = true;
        Handshake::Ack(Vec::new())
    }

    /// An IN token to endpoint `ep` (RM0090 §34.17.6 "IN data transfers"): a packet of
    /// min(XFRSIZ, MPS) bytes when the endpoint is enabled, not NAKing and its FIFO holds it
    /// (NAK while the application is still filling it); the transfer size and packet count
    /// counted down, and at the last packet EPENA cleared and DIEPINT.XFRC set.
    pub fn in_token(&mut self, ep: usize) -> Handshake {
        let Some(e) = self.ins.get(ep) else {
            return Handshake::Silent;
        };
        if ep > 0 && e.ctl & epctl::USBAEP == 0 {
            return Handshake::Silent;
        }
        if e.ctl & epctl::STALL != 0 {
            return Handshake::Stall;
        }
        if e.ctl & epctl::EPENA == 0 || e.nak {
            return Handshake::Nak;
        }
        let (size_mask, pkt_shift, pkt_mask) = if ep == 0 {
            (0x7F, 19, 0x3)
        } else {
            (0x7_FFFF, 19, 0x3FF)
        };
        let xfrsiz = (e.tsiz & size_mask) as usize;
        let n = xfrsiz.min(self.in_mps(ep));
        let words = n.div_ceil(4);
        if e.fifo.len() < words {
            return Handshake::Nak;
        }
        let e = &mut self.ins[ep];
        let mut data = Vec::with_capacity(words * 4);
        for _ in 0..words {
            data.extend_from_slice(&e.fifo.pop_front().unwrap_or(0).to_le_bytes());
        }
        data.truncate(n);
        let pkts = ((e.tsiz >> pkt_shift) & pkt_mask).saturating_sub(1);
        let size = (xfrsiz - n) as u32;
        e.tsiz = (e.tsiz & !(size_mask | (pkt_mask << pkt_shift))) | (pkts << pkt_shift) | size;
        if pkts == 0 {
            e.ctl &= !epctl::EPENA;
            e.int |= epint::XFRC;
        }
        Handshake::Ack(data)
    }
}

/// An endpoint control register's value: as stored, with NAKSTS from the NAK status and
/// USBAEP always set on endpoint 0 (RM0090 §34.16.4 "always active").
fn ep_ctl_read(ctl: u32, nak: bool, n: usize) -> u32 {
    let mut v = ctl;
    if nak {
        v |= epctl::NAKSTS;
    }
    if n == 0 {
        v |= epctl::USBAEP;
    }
    v
}

/// Endpoint `n` at a bus reset: its transfer and halt ended, NAKing, inactive but endpoint 0.
fn ep_reset(ctl: &mut u32, nak: &mut bool, n: usize) {
    *ctl &= !(epctl::EPENA | epctl::STALL);
    if n > 0 {
        *ctl &= !epctl::USBAEP;
    }
    *nak = true;
}

/// An endpoint control register written: CNAK/SNAK act on the NAK status, SD0PID/SODDFRM on
/// the (unmodelled) toggle, EPDIS with EPENA disables the endpoint (EPDISD); the rest stored.
fn ep_ctl_write(ctl: &mut u32, nak: &mut bool, int: &mut u32, v: u32) {
    if v & epctl::CNAK != 0 {
        *nak = false;
    }
    if v & epctl::SNAK != 0 {
        *nak = true;
    }
    let mut stored = v & !(epctl::ACTIONS | epctl::NAKSTS | epctl::EPDIS);
    if v & epctl::EPDIS != 0 && *ctl & epctl::EPENA != 0 {
        stored &= !epctl::EPENA;
        *int |= epint::EPDISD;
    }
    *ctl = stored;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The driver's bring-up as embassy-usb-synopsys-otg does it (AHBIDL polled, CMOD 0,
    /// GCCFG, the soft connect) leaves the pull-up on; CID is the F405's.
    fn connected() -> OtgFs {
        let mut o = OtgFs::new();
        assert_ne!(o.read(0x010) & (1 << 31), 0, "AHBIDL");
        assert_eq!(o.read(0x03C), 0x1200);
        o.write(0x00C, 0x4000_0040);
        assert_eq!(o.read(0x014) & gint::CMOD, 0);
        o.write(0x038, 0x0021_0000);
        o.write(0x804, 2);
        assert!(!o.pulled_up());
        o.write(0x814, epint::STUP);
        o.write(0x810, epint::XFRC);
        o.write(0x018, 0xC00C_3814);
        o.write(0x014, 0xFFFF_FFFF);
        o.write(0x008, 1);
        o.write(0x804, 0);
        assert!(o.pulled_up());
        // The FIFOs as init_fifo sets them: RX 62 words, TX 16 each.
        o.write(0x024, 62);
        o.write(0x028, (16 << 16) | 62);
        o.write(0x104, (16 << 16) | 78);
        o.write(0x108, (16 << 16) | 94);
        o.write(0x81C, 0x0003_0007);
        o
    }

    #[test]
    fn a_bus_reset_and_the_enumeration_raise_the_line_until_cleared() {
        let mut o = connected();
        assert!(!o.irq());
        o.bus_reset();
        assert!(o.irq());
        assert_ne!(o.read(0x014) & gint::USBRST, 0);
        o.write(0x014, gint::USBRST);
        assert!(!o.irq());
        o.enumeration_done();
        assert_eq!((o.read(0x808) >> 1) & 3, 3);
        o.write(0x014, gint::ENUMDNE);
        assert!(!o.irq());
        // The line is gated by GAHBCFG.GINT.
        o.bus_reset();
        o.write(0x008, 0);
        assert!(!o.irq());
    }

    /// A SETUP: two FIFO entries (data, 8 bytes; done), RXFLVL until both are popped, STUP
    /// raised by popping the second (so the handler sees it on its next run), the 8 bytes
    /// read back through the FIFO window; EP0's STALL cleared.
    #[test]
    fn a_setup_packet_reaches_the_application_through_the_fifo() {
        let mut o = connected();
        o.write(0x900, 1 << 21);
        o.write(0xB00, 1 << 21);
        let pkt = [0x80, 6, 0, 1, 0, 0, 64, 0];
        assert_eq!(o.setup(pkt), Handshake::Ack(vec![]));
        assert_eq!(o.peek(0x900) & (1 << 21), 0, "STALL cleared on SETUP");
        assert_eq!(o.peek(0xB00) & (1 << 21), 0);
        assert!(o.irq() && o.read(0x014) & gint::RXFLVL != 0);
        let st = o.read(0x020);
        assert_eq!((st >> 17) & 0xF, 6);
        assert_eq!((st >> 4) & 0x7FF, 8);
        let w0 = o.read(0x1000);
        let w1 = o.read(0x1000);
        assert_eq!(w0.to_le_bytes(), [0x80, 6, 0, 1]);
        assert_eq!(w1.to_le_bytes(), [0, 0, 64, 0]);
        assert_eq!(
            o.peek(0xB08) & epint::STUP,
            0,
            "STUP waits for the done entry"
        );
        let st = o.read(0x020);
        assert_eq!((st >> 17) & 0xF, 4);
        assert_eq!(o.read(0x014) & gint::RXFLVL, 0);
        assert_ne!(o.peek(0xB08) & epint::STUP, 0);
        assert_ne!(o.read(0x014) & gint::OEPINT, 0);
        assert!(o.irq());
        o.write(0xB08, o.peek(0xB08));
        assert!(!o.irq());
    }

    /// IN on EP0: NAK until enabled and filled; a 70-byte transfer the driver writes as one
    /// 64-byte packet (PKTCNT 1) goes out as 64 bytes, then XFRC and EPENA cleared; a short
    /// packet ends a transfer; TXFE and DTXFSTS follow the FIFO's fill.
    #[test]
    fn in_packets_come_from_the_fifo_with_their_transfer_size() {
        let mut o = connected();
        assert_eq!(o.in_token(0), Handshake::Nak);
        assert_eq!(o.peek(0x918), 16, "DTXFSTS: all free");
        assert_ne!(o.peek(0x908) & epint::TXFE, 0);
        o.write(0x910, (1 << 19) | 18);
        o.write(0x900, (1 << 26) | (1 << 31));
        assert_eq!(o.in_token(0), Handshake::Nak, "FIFO not yet filled");
        let bytes: Vec<u8> = (1..=18).collect();
        for c in bytes.chunks(4) {
            let mut b = [0u8; 4];
            b[..c.len()].copy_from_slice(c);
            o.write(0x1000, u32::from_le_bytes(b));
        }
        assert_eq!(o.peek(0x918), 11);
        assert_ne!(
            o.peek(0x908) & epint::TXFE,
            0,
            "11 of 16 words free: half empty"
        );
        assert_eq!(o.in_token(0), Handshake::Ack(bytes));
        assert_eq!(o.peek(0x900) & (1 << 31), 0, "EPENA cleared");
        assert_ne!(o.peek(0x908) & epint::XFRC, 0);
        assert_ne!(o.read(0x014) & gint::IEPINT, 0);
        assert_eq!(o.in_token(0), Handshake::Nak);
        // A zero-length packet: XFRSIZ 0, PKTCNT 1, nothing in the FIFO.
        o.write(0x908, 0xFF);
        o.write(0x910, 1 << 19);
        o.write(0x900, (1 << 26) | (1 << 31));
        assert_eq!(o.in_token(0), Handshake::Ack(vec![]));
        // TXFE reaches DAINT only through DIEPEMPMSK.
        o.write(0x908, 0xFF);
        assert_eq!(o.read(0x818) & 1, 0);
        o.write(0x834, 1);
        assert_eq!(o.read(0x818) & 1, 1);
    }

    /// OUT: taken while NAK is clear, NAK set after each packet (the driver's CNAK re-arms),
    /// the data through the FIFO; a halted endpoint stalls; an inactive one is silent.
    #[test]
    fn out_packets_are_taken_one_per_re_arm() {
        let mut o = connected();
        assert_eq!(
            o.out(1, b"x"),
            Handshake::Silent,
            "not active before the configuration"
        );
        o.write(0xB20, (1 << 15) | (2 << 18) | 64 | (1 << 26) | (1 << 31));
        o.write(0xB30, (1 << 19) | 64);
        assert_eq!(o.out(1, b"status\n"), Handshake::Ack(vec![]));
        assert_eq!(o.out(1, b"more"), Handshake::Nak, "NAK until re-armed");
        let st = o.read(0x020);
        assert_eq!((st >> 17) & 0xF, 2);
        assert_eq!(st & 0xF, 1);
        assert_eq!((st >> 4) & 0x7FF, 7);
        let a = o.read(0x1000).to_le_bytes();
        let b = o.read(0x1000).to_le_bytes();
        assert_eq!(&[a, b].concat()[..7], b"status\n");
        assert_eq!((o.read(0x020) >> 17) & 0xF, 3);
        o.write(0xB20, o.peek(0xB20) | (1 << 26));
        assert_eq!(o.out(1, b"more"), Handshake::Ack(vec![]));
        o.write(0xB20, o.peek(0xB20) | (1 << 21));
        assert_eq!(o.out(1, b"x"), Handshake::Stall);
        // A packet over the endpoint's size is not taken.
        o.write(0xB20, (o.peek(0xB20) & !(1 << 21)) | (1 << 26));
        assert_eq!(o.out(1, &[0; 65]), Handshake::Silent);
    }

    /// The flushes clear at once and empty what they name; CNAK/SNAK read back 0.
    #[test]
    fn flushes_and_action_bits_read_back_as_the_driver_polls_them() {
        let mut o = connected();
        for w in 0..9 {
            o.write(0x1000 * 3, w);
        }
        assert_eq!(o.peek(0x958), 7);
        assert_eq!(
            o.peek(0x948) & epint::TXFE,
            0,
            "7 of 16 free: not half empty"
        );
        o.write(0x010, (1 << 5) | (2 << 6));
        assert_eq!(o.read(0x010), 0x8000_0000);
        assert_eq!(o.peek(0x958), 16, "FIFO 2 flushed");
        o.write(0x920, (1 << 27) | (1 << 15));
        assert_eq!(o.peek(0x920) & (0xF << 26), 0);
        assert_ne!(o.peek(0x920) & (1 << 17), 0, "NAKSTS");
        o.write(0x920, 1 << 26 | (1 << 15));
        assert_eq!(o.peek(0x920) & (1 << 17), 0);
        // EP0 is always active.
        o.write(0x900, 0);
        assert_ne!(o.peek(0x900) & (1 << 15), 0);
    }
}
