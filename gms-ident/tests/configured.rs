//! Commissioning refuses a device that runs on its built-in defaults (`configured=0`): its
//! encoder resolution and sense scale are the paper's rig's, which no user's axis is.

use gms_ident::Error;
use gms_ident::bench::{Bench, commission};

/// A device that answers `status` with `configured` as given and records every request.
struct Fake {
    configured: Option<u8>,
    asked: Vec<String>,
}

impl Bench for Fake {
    fn request(&mut self, line: &str) -> Result<(Vec<String>, String), Error> {
        self.asked.push(line.to_string());
        match line {
            "status" => Ok((
                vec![],
                format!(
                    "mode=gms enabled=0 faults=0 fault_names=none drive=position{}",
                    self.configured
                        .map_or(String::new(), |c| format!(" configured={c}"))
                ),
            )),
            _ => Err(Error::Device(format!("err 9 not in this test: {line}"))),
        }
    }
    fn wait(&mut self, _seconds: f64) -> Result<(), Error> {
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
    // A configured device, or one too old to say, goes on to read its parameters (which this
    // fake does not have).
    for configured in [Some(1), None] {
        let mut dev = Fake {
            configured,
            asked: vec![],
        };
        let e = commission(&mut dev, 1.0).unwrap_err().to_string();
        assert!(e.contains("not in this test"), "{e}");
        assert!(dev.asked.len() > 1, "{:?}", dev.asked);
    }
}
