//! The bench client: a device over a serial port or TCP, and the bench workflows on it.

use super::*;
use gms_core::protocol::ParamId;

/// Two numpy arrays of f64 (the position map's offset and scale).
type ArrayPair<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// A device over a serial port or TCP, speaking the protocol as `gms-tune` does.
#[pyclass(module = "gms", unsendable)]
pub(crate) struct Device {
    link: gms_tune::Link,
}

pub(crate) fn link_err(e: gms_tune::LinkError) -> PyErr {
    err(e)
}

#[pymethods]
impl Device {
    /// Device(port=None, tcp=None, timeout=1.0): a board's serial port, or a TCP address
    /// (`hil-sim serve --tcp`); `timeout` is the reply timeout [s].
    #[new]
    #[pyo3(signature = (port = None, tcp = None, timeout = 1.0))]
    fn new(port: Option<String>, tcp: Option<String>, timeout: f64) -> PyResult<Device> {
        if !(timeout.is_finite() && timeout > 0.0) {
            return Err(err(format!("timeout {timeout}: seconds, above 0")));
        }
        let d = Duration::from_secs_f64(timeout);
        let link = match (port, tcp) {
            (Some(p), None) => gms_tune::Link::serial(&p, d),
            (None, Some(a)) => gms_tune::Link::tcp(&a, d),
            _ => Err("give port or tcp (one of them)".into()),
        }
        .map_err(err)?;
        Ok(Device { link })
    }

    /// request(line) -> str: one protocol line; the text after `ok` (with the lines before it,
    /// newline-separated); an `err` reply raises GmsError with the device's line.
    fn request(&mut self, line: &str) -> PyResult<String> {
        self.link.console_text(line).map_err(link_err)
    }

    /// get(path) -> float | str: a parameter's value (a number where it is one).
    fn get<'py>(&mut self, py: Python<'py>, path: &str) -> PyResult<Bound<'py, PyAny>> {
        let (_, v) = self
            .link
            .ask(gms_core::protocol::Command::Get(path))
            .map_err(link_err)?;
        Ok(match gms_core::protocol::ListValue::parse(v.trim()) {
            gms_core::protocol::ListValue::Number(x) => {
                // The f64 of its decimal text, as the device printed it.
                let x: f64 = v.trim().parse().unwrap_or(f64::from(x));
                x.into_pyobject(py)?.into_any()
            }
            gms_core::protocol::ListValue::Name(n) => n.into_pyobject(py)?.into_any(),
        })
    }

    /// set(path, value): sets a parameter; a refusal raises GmsError and changes nothing.
    fn set(&mut self, path: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let v: String = match value.extract::<f64>() {
            Ok(x) if value.is_instance_of::<PyBool>() => {
                return Err(err(format!("{path}: {x}: not a number or a name")));
            }
            Ok(x) => format!("{x}"),
            Err(_) => value.extract::<String>()?,
        };
        self.link
            .ask(gms_core::protocol::Command::Set(path, &v))
            .map_err(link_err)?;
        Ok(())
    }

    /// list() -> list[dict]: every parameter as {"path", "value", "unit", "range"}.
    fn list<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let rows = gms_tune::params::list(&mut self.link).map_err(link_err)?;
        let l = PyList::empty(py);
        for r in rows {
            let d = PyDict::new(py);
            d.set_item("path", r.path)?;
            d.set_item("value", r.value)?;
            d.set_item("unit", r.unit)?;
            d.set_item("range", r.range)?;
            l.append(d)?;
        }
        Ok(l)
    }

    /// status() -> dict: the `status` reply's keys (numbers where they are).
    fn status<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let st = self.link.status().map_err(link_err)?;
        let d = PyDict::new(py);
        for (k, v) in st.entries() {
            match v {
                gms_core::device::StatusValue::Number(x) => d.set_item(k, x)?,
                gms_core::device::StatusValue::Text(t) => d.set_item(k, t)?,
                gms_core::device::StatusValue::Faults(f) => {
                    d.set_item(k, gms_bench::fault_names(f))?
                }
            }
        }
        Ok(d)
    }

    /// record(fields="t,pos,error,current", rate=1000.0, seconds=1.0) -> dict: the telemetry
    /// stream for `seconds` (wall time) as {field: numpy array}, as `gms-tune record`.
    #[pyo3(signature = (fields = "t,pos,error,current", rate = 1000.0, seconds = 1.0))]
    fn record<'py>(
        &mut self,
        py: Python<'py>,
        fields: &str,
        rate: f64,
        seconds: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(seconds > 0.0 && seconds <= 3600.0 && rate > 0.0 && rate <= 1000.0) {
            return Err(err("seconds in (0, 3600], rate in (0, 1000]"));
        }
        let rows = self.link.record(fields, rate, seconds).map_err(link_err)?;
        let d = PyDict::new(py);
        for (c, n) in fields.split(',').map(str::trim).enumerate() {
            d.set_item(
                n,
                PyArray1::from_vec(py, rows.iter().map(|r| r[c]).collect()),
            )?;
        }
        Ok(d)
    }

    /// step_test(distance=2e-4, seconds=0.5) -> dict: `gms-tune step-test` — the bridge on,
    /// a move by `distance` [rad], `seconds` recorded: {"trace": {t, ref, pos, error, ff,
    /// friction: arrays}, "metrics": the figures of hil-sim run, "rad_per_count": the
    /// device's encoder resolution [rad/count] that the figures in counts use}.
    #[pyo3(signature = (distance = 2e-4, seconds = 0.5))]
    fn step_test<'py>(
        &mut self,
        py: Python<'py>,
        distance: f64,
        seconds: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(distance.is_finite() && seconds > 0.0 && seconds <= 60.0) {
            return Err(err("distance finite, seconds in (0, 60]"));
        }
        let (rows, _, m, rad_per_count) =
            gms_tune::run::step_test(&mut self.link, distance, seconds).map_err(link_err)?;
        let trace = PyDict::new(py);
        for (c, n) in gms_tune::run::STEP_FIELDS.split(',').enumerate() {
            trace.set_item(
                n,
                PyArray1::from_vec(py, rows.iter().map(|r| r[c]).collect()),
            )?;
        }
        let d = PyDict::new(py);
        d.set_item("trace", trace)?;
        d.set_item("metrics", debug_dict(py, &m)?)?;
        d.set_item("rad_per_count", rad_per_count)?;
        Ok(d)
    }

    /// tune_ff(amplitude=2e-3, freq=1.0, seconds=3.0, start=0.5, stop=1.3, steps=9) -> dict:
    /// `gms-tune tune-ff` — the sine test at each ff.gain of a coarse sweep (widened at an
    /// edge), then twice at 9 gains around its optimum: {"curve": [(gain, RMS [rad])],
    /// "optimum", "standard_error" (None without a minimum), "decided", "chosen" (the optimum
    /// when decided, else "before"), "before", "notes"}; the device keeps `before` (set
    /// ff.gain to apply).
    #[pyo3(signature = (amplitude = 2e-3, freq = 1.0, seconds = 3.0, start = 0.5, stop = 1.3, steps = 9))]
    #[allow(clippy::too_many_arguments)]
    fn tune_ff<'py>(
        &mut self,
        py: Python<'py>,
        amplitude: f64,
        freq: f64,
        seconds: f64,
        start: f64,
        stop: f64,
        steps: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let plan = gms_bench::TuneFfPlan {
            amp: amplitude,
            freq,
            seconds,
            from: start,
            to: stop,
            steps,
            ..Default::default()
        };
        plan.check().map_err(err)?;
        let t =
            self.job(|l, ctl| gms_tune::jobs::tune_ff(l, &plan, None, ctl, &mut |_, _, _| {}))?;
        let d = PyDict::new(py);
        d.set_item("curve", t.curve.clone())?;
        d.set_item("chosen", t.chosen)?;
        d.set_item("before", t.before)?;
        d.set_item("decided", t.decided)?;
        d.set_item("optimum", t.optimum.map(|o| o.at))?;
        d.set_item("standard_error", t.optimum.map(|o| o.se))?;
        d.set_item("notes", t.notes.clone())?;
        Ok(d)
    }

    /// commission(speed=1.0) -> dict: `gms-tune commission` — {"lines": a line per step,
    /// "settings": {protocol path: value}}; nothing applied (send the settings to apply).
    #[pyo3(signature = (speed = 1.0))]
    fn commission<'py>(&mut self, py: Python<'py>, speed: f64) -> PyResult<Bound<'py, PyDict>> {
        let c = self
            .job(|l, ctl| gms_tune::jobs::commission(l, speed, None, ctl))?
            .commissioned;
        let d = PyDict::new(py);
        d.set_item("lines", c.lines.clone())?;
        let s = PyDict::new(py);
        for (k, v) in c.settings() {
            s.set_item(k.path(), v)?;
        }
        d.set_item("settings", s)?;
        Ok(d)
    }

    /// frf(loop="open", start=10.0, stop=3000.0, points=40, amplitude=None, velocity=None,
    /// periods=8) -> dict: `gms-tune frf` — a stepped-sine sweep measured on the device;
    /// {"f_hz", "gain_db", "phase_deg", "coherence", "re", "im": numpy arrays in frequency
    /// order, "margins": {gain_margin_db, phase_margin_deg, crossover_hz,
    /// peak_sensitivity_db, …} (loop "open"), "presliding": (stiffness [N·m/rad], inertia
    /// [kg·m²]) (loop "plant" at rest), "model_stiffness": the device's GMS Σk}. `amplitude`
    /// in A (plant, open; default 1 % of lim.i_max) or rad (closed; default 20 counts). The
    /// bridge is off and the settings as they were after it.
    #[pyo3(signature = (r#loop = "open", start = 10.0, stop = 3000.0, points = 40, amplitude = None, velocity = None, periods = 8))]
    #[allow(clippy::too_many_arguments)]
    fn frf<'py>(
        &mut self,
        py: Python<'py>,
        r#loop: &str,
        start: f64,
        stop: f64,
        points: usize,
        amplitude: Option<f64>,
        velocity: Option<f64>,
        periods: u32,
    ) -> PyResult<Bound<'py, PyDict>> {
        use gms_bench::frf::{Loop, Plan};
        let lp = Loop::from_name(r#loop)
            .ok_or_else(|| err(format!("loop {loop:?}: plant, open or closed", loop = r#loop)))?;
        let i_max = gms_bench::get_param(&mut self.link, ParamId::LimIMax).map_err(err)?;
        let rpc = gms_bench::rad_per_count(&mut self.link).map_err(err)?;
        let mut plan = Plan::new(
            lp,
            amplitude.unwrap_or(match lp {
                Loop::Closed => 20.0 * rpc,
                _ => 0.01 * i_max,
            }),
        );
        plan.from_hz = start;
        plan.to_hz = stop;
        plan.points = points;
        plan.velocity = velocity;
        plan.periods = periods;
        let s = self.job(|l, ctl| gms_tune::jobs::frf(l, &plan, None, ctl, &mut |_, _| {}))?;
        let d = PyDict::new(py);
        let col = |f: &dyn Fn(&gms_bench::frf::Point) -> f64| -> Vec<f64> {
            s.points.iter().map(f).collect()
        };
        d.set_item("f_hz", PyArray1::from_vec(py, col(&|p| p.f_hz)))?;
        d.set_item("gain_db", PyArray1::from_vec(py, col(&|p| p.gain_db())))?;
        d.set_item("phase_deg", PyArray1::from_vec(py, col(&|p| p.phase_deg())))?;
        d.set_item("coherence", PyArray1::from_vec(py, col(&|p| p.coherence)))?;
        d.set_item("re", PyArray1::from_vec(py, col(&|p| p.value.re)))?;
        d.set_item("im", PyArray1::from_vec(py, col(&|p| p.value.im)))?;
        match &s.margins {
            Some(m) => {
                let md = PyDict::new(py);
                md.set_item("gain_margin_db", m.gain_margin_db)?;
                md.set_item("gain_margin_hz", m.gain_margin_hz)?;
                md.set_item("phase_margin_deg", m.phase_margin_deg)?;
                md.set_item("phase_margin_hz", m.phase_margin_hz)?;
                md.set_item("crossover_hz", m.crossover_hz)?;
                md.set_item("peak_sensitivity_db", m.peak_sensitivity_db)?;
                md.set_item("peak_sensitivity_hz", m.peak_sensitivity_hz)?;
                d.set_item("margins", md)?;
            }
            None => d.set_item("margins", py.None())?,
        }
        d.set_item("presliding", s.presliding)?;
        d.set_item("model_stiffness", s.model_stiffness)?;
        Ok(d)
    }

    /// map(speed=1.0, revs=1.0, bins=512, order=64, apply=False) -> dict: `gms-tune map` —
    /// runs both ways over whole periods of one motor revolution, the harmonic fit:
    /// {"angle", "offset" [N·m], "scale": numpy arrays per bin, "friction": the model's
    /// sliding friction the scale is of [N·m], "forward", "backward": (angle, torque) samples};
    /// `apply` writes it into the device and switches it on.
    #[pyo3(signature = (speed = 1.0, revs = 1.0, bins = 512, order = 64, apply = false))]
    fn map<'py>(
        &mut self,
        py: Python<'py>,
        speed: f64,
        revs: f64,
        bins: usize,
        order: usize,
        apply: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let plan = gms_bench::posmap::MapPlan {
            speed,
            periods: revs,
            bins,
            order,
            ..Default::default()
        };
        plan.check().map_err(err)?;
        let (data, map) = self.job(|l, ctl| gms_tune::jobs::map(l, &plan, None, ctl))?;
        if apply {
            gms_bench::posmap::write(&mut self.link, &map, true).map_err(err)?;
        }
        let d = PyDict::new(py);
        d.set_item("angle", PyArray1::from_vec(py, map.angle.clone()))?;
        d.set_item("offset", PyArray1::from_vec(py, map.offset.clone()))?;
        d.set_item("scale", PyArray1::from_vec(py, map.scale.clone()))?;
        d.set_item("friction", map.friction)?;
        d.set_item("forward", data.forward)?;
        d.set_item("backward", data.backward)?;
        Ok(d)
    }

    /// learn(amplitude=0.05, freq=1.0, trajectory=None, iterations=10, gain=0.3,
    /// q_filter=400.0, lead=0.0, apply=False) -> dict: `gms-tune learn` — the sine
    /// x = A (1 − cos 2πft) from where the axis holds, or `trajectory` (rows of (t [s],
    /// x [rad]) over one period) played from the device's tables, the correction learned after
    /// each period: {"rms", "peak": numpy arrays per iteration [counts], "errors": 2-D array
    /// (iteration × point) [counts], "t": the points' times [s], "correction": the correction
    /// kept [N·m], "stopped": None or why}; `apply` leaves the correction playing.
    #[pyo3(signature = (amplitude = gms_bench::learn::SINE.0, freq = gms_bench::learn::SINE.1, trajectory = None, iterations = gms_bench::learn::ITERATIONS, gain = gms_bench::learn::GAIN, q_filter = gms_bench::learn::Q_HZ, lead = 0.0, apply = false))]
    #[allow(clippy::too_many_arguments)]
    fn learn<'py>(
        &mut self,
        py: Python<'py>,
        amplitude: f64,
        freq: f64,
        trajectory: Option<Vec<(f64, f64)>>,
        iterations: usize,
        gain: f64,
        q_filter: f64,
        lead: f64,
        apply: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        use gms_bench::learn::{LearnPlan, Path};
        let plan = LearnPlan {
            path: match trajectory {
                Some(rows) => Path::Trajectory(rows),
                None => Path::Sine { amplitude, freq },
            },
            iterations,
            gain,
            q_hz: q_filter,
            lead_s: lead,
            ..LearnPlan::default()
        };
        plan.check().map_err(err)?;
        let l = self
            .job(|link, ctl| gms_tune::jobs::learn(link, &plan, None, apply, ctl, &mut |_| {}))?;
        let d = PyDict::new(py);
        d.set_item(
            "rms",
            PyArray1::from_vec(py, l.iterations.iter().map(|i| i.rms).collect()),
        )?;
        d.set_item(
            "peak",
            PyArray1::from_vec(py, l.iterations.iter().map(|i| i.peak).collect()),
        )?;
        let errors = numpy::PyArray2::from_vec2(py, &l.errors).map_err(err)?;
        d.set_item("errors", errors)?;
        let dt = l.table.as_ref().map_or(0.0, |t| t.dt());
        d.set_item(
            "t",
            PyArray1::from_vec(py, (0..l.correction.len()).map(|k| k as f64 * dt).collect()),
        )?;
        d.set_item("correction", PyArray1::from_vec(py, l.correction.clone()))?;
        let r = l.repeat();
        d.set_item("repeating", r.map(|r| r.repeating))?;
        d.set_item("not_repeating", r.map(|r| r.not_repeating))?;
        d.set_item("stopped", l.stopped.map(|s| format!("{s:?}")))?;
        Ok(d)
    }

    /// map_read() -> (offset, scale): the device's table as numpy arrays (its `map.bins` bins;
    /// N·m and -).
    fn map_read<'py>(&mut self, py: Python<'py>) -> PyResult<ArrayPair<'py>> {
        let t = gms_bench::posmap::read(&mut self.link).map_err(err)?;
        let (o, s): (Vec<f64>, Vec<f64>) = t.into_iter().unzip();
        Ok((PyArray1::from_vec(py, o), PyArray1::from_vec(py, s)))
    }

    /// map_write(offset, scale, period=2π, enable=False): writes a table of 8 to 512 bins over
    /// `period` [rad] into the device (the map off while it is written), and switches it on if
    /// `enable`.
    #[pyo3(signature = (offset, scale, period = std::f64::consts::TAU, enable = false))]
    fn map_write(
        &mut self,
        offset: PyReadonlyArray1<'_, f64>,
        scale: PyReadonlyArray1<'_, f64>,
        period: f64,
        enable: bool,
    ) -> PyResult<usize> {
        let (o, s) = (offset.as_slice()?.to_vec(), scale.as_slice()?.to_vec());
        if o.len() != s.len() {
            return Err(err(format!(
                "offset and scale of different lengths ({} and {})",
                o.len(),
                s.len()
            )));
        }
        let n = o.len();
        let map = gms_bench::posmap::PosMap {
            period,
            angle: (0..n).map(|i| period * i as f64 / n as f64).collect(),
            offset: o,
            scale: s,
            friction: f64::NAN,
            residual: (f64::NAN, f64::NAN),
        };
        gms_bench::posmap::write(&mut self.link, &map, enable).map_err(err)
    }

    /// identify(report="identify-report", blocks=6) -> dict: `gms-tune identify` — the
    /// experiments on the device (CSVs in `report`), the fits: {"params": the parameter
    /// file's text, "report": lines, "presliding": [(x, f)], "sliding": [(v, f)]}; nothing
    /// applied.
    #[pyo3(signature = (report = PathBuf::from("identify-report"), blocks = 6))]
    fn identify<'py>(
        &mut self,
        py: Python<'py>,
        report: PathBuf,
        blocks: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (_, plans) =
            gms_tune::jobs::identify_plans(&mut self.link, &gms_bench::Ranges::default())
                .map_err(err)?;
        let j = self
            .job(|l, ctl| gms_tune::jobs::identify(l, &plans, &report, None, blocks, false, ctl))?;
        let (g, id, text) = (j.gathered, j.identified, j.text);
        let d = PyDict::new(py);
        d.set_item("params", text)?;
        d.set_item("report", id.report.clone())?;
        d.set_item("presliding", g.presliding)?;
        d.set_item("sliding", g.sliding)?;
        Ok(d)
    }
}

/// Hooks that report nothing (Python's caller waits for the result).
pub(crate) struct Quiet;

impl gms_tune::run::Hooks for Quiet {
    fn stage(&mut self, _: &str, _: f64) {}
    fn waited(&mut self, _: f64) {}
}

impl Device {
    /// Runs a job with the command line's and the window's code (`gms_tune::jobs`).
    fn job<T>(
        &mut self,
        f: impl FnOnce(
            &mut gms_tune::Link,
            &mut gms_tune::jobs::Control<'_>,
        ) -> Result<T, gms_bench::Error>,
    ) -> PyResult<T> {
        let mut quiet = Quiet;
        let mut ctl = gms_tune::jobs::Control {
            stop: std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)),
            why: "stopped",
            hooks: &mut quiet,
        };
        f(&mut self.link, &mut ctl).map_err(|e| err(format!("{e}; the bridge is off")))
    }
}
