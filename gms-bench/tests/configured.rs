//! Commissioning refuses a device that runs on its built-in defaults (`configured=0`): its
//! encoder resolution and sense scale are the paper's rig's, which no user's axis is.

use gms_bench::commission;
use gms_core::control::controller::FfMode;
use gms_core::device::{DriveKind, StatusReply};
use gms_core::drive::Faults;

/// A device that answers `status` with `configured` as given and records every request.
struct Fake {
    configured: Option<u8>,
    asked: Vec<String>,
}

impl gms_link::DeviceLink for Fake {
    fn request(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        let line = c.to_string();
        self.asked.push(line.clone());
        match line.as_str() {
            "status" => {
                // The device core's own reply at rest, with `configured` as given (or left out).
                let mut text = String::new();
                StatusReply {
                    mode: FfMode::Gms,
                    enabled: false,
                    faults: Faults::NONE,
                    t: 1.0,
                    pos: 0.0,
                    error_counts: 0.0,
                    moving: false,
                    current: 0.0,
                    ff: 0.0,
                    duty: 0.0,
                    step_us_worst: 0.0,
                    step_us_mean: 0.0,
                    sense_offset: 2048.0,
                    missed: 0,
                    late: 0,
                    duty_max: 1.0,
                    duty_limited: 0,
                    supply: 12.0,
                    drive: DriveKind::Position,
                    configured: self.configured == Some(1),
                }
                .write(&mut text)
                .unwrap();
                if self.configured.is_none() {
                    text = text.replace(" configured=0", "");
                }
                Ok((vec![], text))
            }
            _ => Err(gms_link::Error::Reply(format!("not in this test: {line}"))),
        }
    }
    fn pass(&mut self, _seconds: f64) -> Result<(), gms_link::Error> {
        Ok(())
    }
}

#[test]
fn commissioning_refuses_an_unconfigured_device_before_anything_moves() {
    let mut dev = Fake {
        configured: Some(0),
        asked: vec![],
    };
    let e = commission(&mut dev, 1.0).unwrap_err().to_string();
    assert!(
        e.contains("never configured") && e.contains("enc.counts_per_rev"),
        "{e}"
    );
    // Only the status was read: nothing set, nothing enabled.
    assert_eq!(dev.asked, ["status"]);
    // A configured device goes on to read its parameters (which this fake does not have).
    let mut dev = Fake {
        configured: Some(1),
        asked: vec![],
    };
    let e = commission(&mut dev, 1.0).unwrap_err().to_string();
    assert!(e.contains("not in this test"), "{e}");
    assert!(dev.asked.len() > 1, "{:?}", dev.asked);
    // A device that does not say is refused too, saying what is missing.
    let mut dev = Fake {
        configured: None,
        asked: vec![],
    };
    let e = commission(&mut dev, 1.0).unwrap_err().to_string();
    assert!(e.contains("the status reply has no configured"), "{e}");
    assert_eq!(dev.asked, ["status"]);
}
