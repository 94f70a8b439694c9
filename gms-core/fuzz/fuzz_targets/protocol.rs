//! Fuzz target: any bytes on the wire through the line reader and the whole command set.
//! `RUSTC_BOOTSTRAP=1 cargo fuzz run protocol` from `gms-core/` (cargo-fuzz needs nightly
//! features; RUSTC_BOOTSTRAP enables them on the stable toolchain).
#![no_main]

use core::fmt::Write;

use gms_core::protocol::{self, Device, LineReader, Settings};
use gms_core::selftest;
use libfuzzer_sys::fuzz_target;

struct Dev(Settings, bool);

impl Device for Dev {
    fn settings(&self) -> &Settings {
        &self.0
    }
    fn apply(&mut self, new: Settings) {
        assert!(new.validate().is_ok(), "an invalid set reached the device");
        self.0 = new;
    }
    fn save(&mut self) -> Result<(), &'static str> {
        if self.1 { Err("disable first") } else { Ok(()) }
    }
    fn load(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
    fn defaults(&mut self) {
        self.0 = selftest::controller_params();
    }
    fn enable(&mut self) -> Result<(), &'static str> {
        self.1 = true;
        Ok(())
    }
    fn disable(&mut self) {
        self.1 = false;
    }
    fn status(&self, out: &mut dyn Write) -> core::fmt::Result {
        write!(out, "enabled={}", self.1)
    }
    fn clear(&mut self) {}
    fn move_to(&mut self, _: f32, _: Option<f32>) -> Result<(), &'static str> {
        Ok(())
    }
    fn stream(&mut self, _: &str, _: f32) -> Result<(), &'static str> {
        Ok(())
    }
    fn stream_off(&mut self) {}
}

fuzz_target!(|data: &[u8]| {
    let mut dev = Dev(selftest::controller_params(), false);
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
