//! The device's settings as one value on the host (`gms_bench::settings`), on the virtual
//! device in-process: read whole, written as one staged set (all or nothing), and put back
//! around a run whatever ends it.

use gms_bench::Error;
use gms_bench::settings::{self, Snapshot, changes, restoring};
use gms_bench::{Bench, get_param};
use gms_core::protocol::ParamId;
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

fn device() -> LocalDevice {
    LocalDevice::new(&Scenario::default()).unwrap()
}

/// `get` of parameters as the device answers them (f32 values written in decimal).
fn got(dev: &mut LocalDevice, paths: &[ParamId]) -> Vec<f32> {
    paths
        .iter()
        .map(|p| get_param(dev, *p).unwrap() as f32)
        .collect()
}

const PATHS: [ParamId; 6] = [
    ParamId::PosKp,
    ParamId::LimPosMin,
    ParamId::LimPosMax,
    ParamId::FfGain,
    ParamId::GmsFs,
    ParamId::EncCountsPerRev,
];

#[test]
fn the_settings_read_whole_are_the_device_s() {
    let mut dev = device();
    for (p, v) in [
        ("pos.kp", "0.25"),
        ("ff.gain", "0.875"),
        ("lim.pos_max", "3.5"),
    ] {
        dev.console(&format!("set {p} {v}")).unwrap();
    }
    let s = settings::read(&mut dev).unwrap();
    assert_eq!((s.pid.kp, s.ff.gain, s.pos_max), (0.25, 0.875, 3.5));
    // Every number read back as `get` gives it.
    let mut text = String::new();
    for &id in ParamId::ALL {
        let p = id.param();
        if let gms_core::protocol::Access::Number { get, .. } = p.access {
            let on_device = get_param(&mut dev, id).unwrap() as f32;
            assert_eq!(get(&s), on_device, "{}", p.path);
            text.push_str(p.path);
        }
    }
    assert!(text.contains("enc.counts_per_rev"));
    // Read twice: nothing differs.
    assert!(changes(&s, &settings::read(&mut dev).unwrap()).is_empty());
}

#[test]
fn a_written_set_is_all_or_nothing() {
    let mut dev = device();
    let before = settings::read(&mut dev).unwrap();
    let mut to = before;
    to.pid.kp *= 2.0;
    to.pos_min = -2.0;
    to.pos_max = 2.0;
    to.ff.gain = 0.5;
    let n = settings::write(&mut dev, &to).unwrap();
    assert_eq!(n, 4);
    assert_eq!(
        got(
            &mut dev,
            &[
                ParamId::PosKp,
                ParamId::LimPosMin,
                ParamId::LimPosMax,
                ParamId::FfGain
            ]
        ),
        [before.pid.kp * 2.0, -2.0, 2.0, 0.5]
    );
    // A set the device refuses as a whole (Fs below Fc) changes nothing, not even the
    // parameters that were fine on their own.
    let now = got(&mut dev, &PATHS);
    let mut bad = to;
    bad.pid.kp = 0.125;
    bad.ff.actuator.stribeck.fc = bad.ff.actuator.stribeck.fs * 2.0;
    let e = settings::write(&mut dev, &bad).unwrap_err();
    assert!(e.to_string().contains("nothing changed"), "{e}");
    assert_eq!(got(&mut dev, &PATHS), now);
}

/// A bench that stops taking ordinary requests after `left` of them, as a stopped run does
/// (Ctrl-C), while the requests that end a run still go out.
struct Stopping<'a> {
    dev: &'a mut LocalDevice,
    left: usize,
}

impl gms_link::DeviceLink for Stopping<'_> {
    fn request(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        if self.left == 0 {
            return Err(gms_link::Error::Lost("interrupted".into()));
        }
        self.left -= 1;
        self.dev.request(c)
    }
    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        self.dev.pass(seconds)
    }
    fn request_to_end(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        self.dev.request(c)
    }
}

#[test]
fn a_run_leaves_the_settings_as_they_were_however_it_ends() {
    let mut dev = device();
    let before = got(&mut dev, &PATHS);
    let snap = Snapshot::take(&mut dev).unwrap();
    // Done: what the run set is undone, the bridge off.
    let r = restoring(&mut dev, |b| {
        b.console("set lim.pos_min -0.1")?;
        b.console("set pos.kp 0.125")?;
        b.console("set ff.gain 0.3")?;
        b.console("enable")?;
        b.wait(0.05)?;
        Ok(7)
    });
    assert_eq!(r, Ok(7));
    assert_eq!(got(&mut dev, &PATHS), before);
    assert!(!gms_bench::status(&mut dev).unwrap().enabled);
    // Failed half-way: the run's error, the settings back.
    let r: Result<(), Error> = restoring(&mut dev, |b| {
        b.console("set lim.pos_max 0.1")?;
        b.console("set pos.nonsense 1")?;
        Ok(())
    });
    assert!(r.unwrap_err().to_string().contains("unknown parameter"));
    assert_eq!(got(&mut dev, &PATHS), before);
    // Stopped (every ordinary request refused after the third): still put back.
    let mut stopping = Stopping {
        dev: &mut dev,
        left: 3,
    };
    let r: Result<(), Error> = restoring(&mut stopping, |b| {
        b.set(ParamId::FfGain, 0.2)?;
        b.set(ParamId::EncDir, -1.0)?;
        b.set(ParamId::FfGain, 0.1)?;
        b.set(ParamId::PosKp, 9.0)?;
        Ok(())
    });
    assert_eq!(r, Err(Error::Link("interrupted".into())));
    assert_eq!(got(&mut dev, &PATHS), before);
    assert_eq!(got(&mut dev, &[ParamId::EncDir]), [1.0]);
    assert!(changes(snap.settings(), &settings::read(&mut dev).unwrap()).is_empty());
}
