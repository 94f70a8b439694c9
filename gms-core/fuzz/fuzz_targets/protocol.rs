//! Fuzz target: any bytes on the wire through the line reader and the whole command set.
//! `RUSTC_BOOTSTRAP=1 cargo fuzz run protocol` from `gms-core/` (cargo-fuzz needs nightly
//! features; RUSTC_BOOTSTRAP enables them on the stable toolchain).
#![no_main]

use core::fmt::Write;

use gms_core::protocol::{self, Device, LineReader, Settings};
use gms_core::selftest;
use libfuzzer_sys::fuzz_target;

/// A device that keeps its settings and staging as the real one does (every set that reaches
/// it must be valid) and accepts every motion.
struct Dev {
    s: Settings,
    staged: Option<Settings>,
    enabled: bool,
}

impl Device for Dev {
    fn settings(&self) -> &Settings {
        &self.s
    }
    fn staged(&mut self) -> &mut Option<Settings> {
        &mut self.staged
    }
    fn apply(&mut self, new: Settings) -> Result<(), &'static str> {
        assert!(new.validate().is_ok(), "an invalid set reached the device");
        self.s = new;
        Ok(())
    }
    fn save(&mut self) -> Result<(), &'static str> {
        if self.enabled { Err("disable before save") } else { Ok(()) }
    }
    fn load(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
    fn defaults(&mut self) -> Result<(), &'static str> {
        self.s = selftest::controller_params();
        Ok(())
    }
    fn enable(&mut self) -> Result<(), &'static str> {
        self.enabled = true;
        Ok(())
    }
    fn enable_current(&mut self) -> Result<(), &'static str> {
        self.enabled = true;
        Ok(())
    }
    fn disable(&mut self) -> Result<(), &'static str> {
        self.enabled = false;
        Ok(())
    }
    fn status(&mut self) -> gms_core::device::StatusReply {
        gms_core::device::StatusReply {
            enabled: self.enabled,
            ..Default::default()
        }
    }
    fn clear(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
    fn move_to(&mut self, _: f32, _: Option<f32>) -> Result<(), &'static str> {
        Ok(())
    }
    fn current(&mut self, _: f32, _: Option<f32>) -> Result<(), &'static str> {
        Ok(())
    }
    fn velocity(
        &mut self,
        _: f32,
        _: Option<gms_core::control::reference::Sweep>,
    ) -> Result<(), &'static str> {
        Ok(())
    }
    fn hold(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
    fn capture_arm(&mut self, _: &str, _: u32, _: u32, _: bool) -> Result<(), &'static str> {
        Ok(())
    }
    fn capture_off(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
    fn capture_status(&mut self) -> protocol::CaptureStatus {
        protocol::CaptureStatus {
            state: gms_core::device::CaptureState::Idle,
            samples: 0,
            capacity: 0,
            origin: 0.0,
        }
    }
    fn capture_read(&mut self, _: u32, _: u32, _: &mut dyn Write) -> Result<(), &'static str> {
        Err("no capture")
    }
    fn stream(&mut self, _: &str, _: f32) -> Result<(), &'static str> {
        Ok(())
    }
    fn stream_off(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
}

fuzz_target!(|data: &[u8]| {
    let mut dev = Dev {
        s: selftest::controller_params(),
        staged: None,
        enabled: false,
    };
    let mut rd = LineReader::default();
    for &b in data {
        if let Some(line) = rd.push(b) {
            let mut out = String::new();
            protocol::execute(&mut dev, line, &mut out).unwrap();
            // Every reply ends with one line the host's reader takes as its end (`ok …` or
            // `err CODE …` with a code the protocol has); its other lines are not ends.
            let mut lines = out.lines();
            if let Some(last) = lines.next_back() {
                assert!(matches!(protocol::Reply::parse(last), Ok(Some(_))), "{out:?}");
                for l in lines {
                    assert_eq!(protocol::Reply::parse(l), Ok(None), "{out:?}");
                }
            }
        }
    }
});
