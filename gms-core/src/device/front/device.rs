//! The protocol's requests on a device ([`Device`] for [`Front`]): what `set`, `move`,
//! `save`, `status`, `stream`, `capture`, `frf` and `map` do.

use super::*;

/// Position steps a speed profile is advanced on the protocol side from the status it is
/// planned on: the status published at step `n`'s exchange, the request taken at the next,
/// when `n + 1` steps have run, where the loop catches the profile up to step `n + 1` and its
/// reference side then works out step `n + 2`'s. Advanced here, the loop has nothing to catch
/// up with unless the request waited longer.
const VELOCITY_AHEAD: u64 = 1;

impl<L: LoopLink, S: ParamStore> Device for Front<L, S> {
    fn new_session(&mut self) {
        self.disconnected();
    }

    fn settings(&self) -> &Settings {
        &self.settings
    }

    fn staged(&mut self) -> &mut Option<Settings> {
        &mut self.staged
    }

    fn supply_confirmed(&mut self) {
        self.supply_confirmed = true;
    }

    fn apply(&mut self, new: Settings) -> Result<(), &'static str> {
        let a = prepare(&new, &self.board)?;
        // The new controller built in the spare storage here, on the protocol side; the loop
        // only swaps it in.
        let ctrl = self.bufs.spare(&mut self.link)?;
        *ctrl = a.ctrl;
        let staged = Staged {
            ctrl,
            limits: a.limits,
            psc: a.psc,
            arr: a.arr,
            taken: false,
        };
        self.post(|r| r.apply = Some(staged))?;
        // A commit (or a load) that changed the supply confirms it.
        self.supply_confirmed |= new.v_supply != self.settings.v_supply;
        self.settings = new;
        self.configured = true;
        Ok(())
    }

    // Not inlined, as `startup`: the record in this frame, not the link task's.
    #[inline(never)]
    fn save(&mut self) -> Result<(), &'static str> {
        if self.status_now().enabled {
            return Err("disable before save");
        }
        let rec = encode_settings(&self.settings);
        let r = self.store.save(&rec);
        // The position map beside it (a store that keeps one, a loop that has one).
        let m = if r.is_ok() { self.save_map() } else { Ok(()) };
        // A flash write stalls the CPU on a board: the statistics start afresh.
        let _ = self.post(|r| r.reset_stats = true);
        r.map_err(|_| "store write failed")?;
        m
    }

    // Not inlined, as `save`.
    #[inline(never)]
    fn load(&mut self) -> Result<(), &'static str> {
        if self.status_now().enabled {
            return Err("disable before load");
        }
        let rec = match self.store.load() {
            Ok(Some(rec)) => rec,
            Ok(None) => return Err("nothing saved"),
            Err(_) => return Err("store read failed"),
        };
        let s = decode_settings(&rec, &self.defaults).map_err(|_| "stored set invalid")?;
        self.apply(s.settings)?;
        self.supply_confirmed = true;
        self.load_map()
    }

    fn defaults(&mut self) -> Result<(), &'static str> {
        let d = self.defaults;
        self.apply(d)?;
        self.configured = self.defaults_configured;
        self.supply_confirmed = self.defaults_configured;
        Ok(())
    }

    fn enable(&mut self) -> Result<(), &'static str> {
        if !self.status_now().faults.is_empty() {
            return Err("fault latched (clear first)");
        }
        self.may_drive()?;
        self.sense_reaches_i_max()?;
        self.supply_in_range()?;
        self.post(|r| r.enable = true)?;
        if self.status_now().enabled {
            Ok(())
        } else {
            Err("not enabled (fault)")
        }
    }

    fn enable_current(&mut self) -> Result<(), &'static str> {
        if !self.status_now().faults.is_empty() {
            return Err("fault latched (clear first)");
        }
        self.may_drive()?;
        self.sense_reaches_i_max()?;
        self.supply_in_range()?;
        // One exchange: the loop takes the enable and the current in the same step.
        self.post(|r| {
            r.enable = true;
            r.current = Some(0.0);
            r.current_steps = None;
        })?;
        if self.status_now().enabled {
            Ok(())
        } else {
            Err("not enabled (fault)")
        }
    }

    fn disable(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.disable = true)
    }

    fn status(&mut self) -> StatusReply {
        let st = self.status_now();
        let rpc = self.settings.rad_per_count();
        let clock = self.board.limits.clock_hz;
        StatusReply {
            mode: self.settings.ff.mode,
            enabled: st.enabled,
            faults: st.faults,
            t: st.steps as f64 / st.pos_rate_hz.max(1.0) as f64,
            pos: st.pos as f64 * rpc as f64,
            error_counts: st.error / rpc,
            moving: st.moving,
            current: st.current,
            ff: st.ff,
            duty: st.duty,
            step_us_worst: drive::cycles_to_us(st.stats.worst() as f32, clock),
            step_us_mean: drive::cycles_to_us(st.stats.mean(), clock),
            sense_offset: st.sense_offset,
            missed: st.stats.missed(),
            late: st.stats.late(),
            duty_max: self.board.sense.duty_max(self.settings.cur_rate_hz),
            duty_limited: st.stats.limited(),
            supply: self.supply_v().unwrap_or(self.settings.v_supply),
            drive: st.drive.kind(),
            configured: self.configured,
        }
    }

    fn clear(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.clear = true)
    }

    fn capture_arm(
        &mut self,
        fields: &str,
        every: u32,
        samples: u32,
        on_next: bool,
    ) -> Result<(), &'static str> {
        let (idx, n) = capture_fields(fields)?;
        if u64::from(samples) * u64::from(n) > u64::from(self.board.capture_values) {
            return Err("more than the capture buffer holds (samples × fields)");
        }
        let spec = CaptureSpec {
            fields: idx,
            nfields: n,
            every,
            samples,
            on_next,
        };
        self.post(|r| r.capture = Some(CaptureRequest::Arm(spec)))
    }

    fn capture_off(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.capture = Some(CaptureRequest::Off))
    }

    fn capture_status(&mut self) -> protocol::CaptureStatus {
        let st = self.status_now();
        protocol::CaptureStatus {
            state: st.capture,
            samples: st.captured,
            capacity: self.board.capture_values,
            origin: st.capture_origin as f64 * self.settings.rad_per_count() as f64,
        }
    }

    fn capture_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        let st = self.status_now();
        if st.capture != CaptureState::Done {
            return Err("no capture to read (capture: state)");
        }
        let end = start.saturating_add(count).min(st.captured);
        self.write_chunks(
            (start, end),
            |r, start, max| r.capture = Some(CaptureRequest::Read { start, max }),
            "capture read failed",
            out,
        )
    }

    fn current(&mut self, amps: f32, seconds: Option<f32>) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        if !(amps.is_finite() && amps.abs() <= self.settings.i_max) {
            return Err("beyond lim.i_max");
        }
        let steps = match seconds {
            None => None,
            Some(s) if s > 0.0 && s <= 60.0 => {
                // Float to int casts saturate; at most 60 s of steps.
                Some((s * self.settings.pos_rate_hz + 0.5) as u32)
            }
            Some(_) => return Err("SECONDS must be in (0, 60]"),
        };
        self.post(|r| {
            r.current = Some(amps);
            r.current_steps = steps;
        })
    }

    fn velocity(&mut self, vel: f32, sweep: Option<Sweep>) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        let rpc = self.settings.rad_per_count();
        let dt = self.settings.dt_pos();
        let mut profile = VelocityProfile::new(st.reference, vel, sweep, MOVE_AMAX, rpc)
            .map_err(|_| "bad velocity (|VEL| + AMP <= 20 rad/s; frequencies and duration > 0)")?
            .for_step(dt);
        // Advanced to the step the loop takes the request at (the loop's arithmetic, bit for
        // bit): each catch-up step is one more `VelocityProfile::next` in the step that takes
        // the request, which with two of them was the longest, 2,538 cycles in `rehost check`
        // (2,122 now).
        for _ in 0..VELOCITY_AHEAD {
            profile.next(dt);
        }
        let req = VelocityRequest {
            profile,
            from_step: st.steps.saturating_add(VELOCITY_AHEAD),
        };
        self.post(|r| r.velocity = Some(req))
    }

    fn hold(&mut self) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        match st.drive {
            Drive::Current(_) => self.post(|r| r.hold_here = true),
            Drive::Velocity => {
                // Stop where the acceleration limit allows, continuing from the reference.
                let rpc = self.settings.rad_per_count();
                let v = st.reference.vel;
                let here = (st.reference.pos as f64 / SUB_PER_COUNT as f64 * rpc as f64) as f32;
                let target = here + v * v.abs() / (2.0 * MOVE_AMAX);
                let plan = Motion::plan(st.reference, target, None, rpc).map_err(|_| "bad stop")?;
                let req = MoveRequest {
                    plan,
                    from_step: st.steps,
                };
                self.post(|r| r.motion = Some(req))
            }
            Drive::Position => Ok(()),
        }
    }

    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        let rpc = self.settings.rad_per_count();
        let limits = self.board.limits(&self.settings);
        let target = pos / rpc;
        if !(target >= limits.pos_min as f32 && target <= limits.pos_max as f32) {
            return Err("beyond the soft limits");
        }
        // From the loop's reference now (position, velocity, acceleration): a move under
        // way is continued, not restarted.
        let plan = Motion::plan(st.reference, pos, vel, rpc).map_err(|_| "bad move")?;
        let req = MoveRequest {
            plan,
            from_step: st.steps,
        };
        self.post(|r| r.motion = Some(req))
    }

    fn stream(&mut self, fields: &str, rate_hz: f32) -> Result<(), &'static str> {
        if rate_hz > MAX_STREAM_HZ {
            return Err("rate above 1000 Hz");
        }
        let mut idx = [0u8; FIELDS.len()];
        let mut n = 0;
        for f in fields.split(',') {
            let i = FIELDS
                .iter()
                .position(|x| *x == f)
                .filter(|&i| self.board.has_truth || FIELDS.get(i) != Some(&"friction_true"))
                .ok_or("unknown field (t, pos, ref, error, ff, current, friction)")?;
            let slot = idx.get_mut(n).ok_or("too many fields")?;
            *slot = i as u8;
            n += 1;
        }
        let every = (self.settings.pos_rate_hz / rate_hz + 0.5).max(1.0) as u32;
        self.post(|r| r.stream_every = Some(every))?;
        self.fields = idx;
        self.nfields = n;
        Ok(())
    }

    fn stream_off(&mut self) -> Result<(), &'static str> {
        self.nfields = 0;
        self.post(|r| r.stream_every = Some(0))
    }

    fn estimate(&mut self, which: protocol::Estimate) -> f32 {
        match which {
            protocol::Estimate::AdaptScale => self.status_now().adapt_scale,
        }
    }

    fn frf_start(
        &mut self,
        injection: Injection,
        f_hz: f32,
        amp: f32,
        periods: u32,
        settle: u32,
    ) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        if matches!(st.drive, Drive::Current(_)) {
            return Err("in current mode: no position loop (hold first)");
        }
        if periods == 0 {
            return Err("PERIODS must be at least 1");
        }
        let rate = self.settings.pos_rate_hz;
        let spec =
            FrfSpec::new(injection, f_hz, amp, periods, settle, rate).map_err(|e| e.reason())?;
        if spec.steps() as f32 > FRF_MAX_S * rate {
            return Err("longer than 600 s (fewer periods)");
        }
        match injection {
            Injection::Current => {
                if amp > self.settings.i_max {
                    return Err("AMP beyond lim.i_max");
                }
            }
            Injection::Position => {
                let w = core::f32::consts::TAU * f_hz;
                if amp * w > crate::control::reference::VELOCITY_MAX {
                    return Err("AMP × 2π F_HZ beyond the speed limit (20 rad/s)");
                }
                let rpc = self.settings.rad_per_count();
                let limits = self.board.limits(&self.settings);
                let here = (st.reference.pos as f64 / SUB_PER_COUNT as f64) as f32;
                let reach = amp / rpc;
                if !(here - reach >= limits.pos_min as f32 && here + reach <= limits.pos_max as f32)
                {
                    return Err("AMP beyond the soft limits from here");
                }
            }
        }
        self.post(|r| r.frf = Some(FrfRequest::Start(spec)))
    }

    fn map_write(&mut self, start: u32, pairs: &str) -> Result<(), &'static str> {
        if self.settings.map.enable != 0.0 {
            return Err("map.enable is 1: set it to 0 to write the table");
        }
        let mut values = [0.0f32; 2 * MAP_WRITE_BINS];
        let mut n = 0usize;
        for pair in pairs.split_ascii_whitespace() {
            // The comma by hand: `split_once` brings a panicking branch into the link.
            let comma = pair.bytes().position(|c| c == b',').unwrap_or(pair.len());
            let (o, s) = (pair.get(..comma), pair.get(comma.saturating_add(1)..));
            let (Some(o), Some(s)) = (
                o.and_then(protocol::parse_f32),
                s.and_then(protocol::parse_f32),
            ) else {
                return Err("a bin is OFFSET,SCALE (N·m, -)");
            };
            if !crate::control::posmap::valid_bin(o, s) {
                return Err("a bin's offset beyond 10 N·m or scale outside 0 … 2");
            }
            match values.get_mut(2 * n..2 * n + 2) {
                Some([a, b]) => (*a, *b) = (o, s),
                _ => return Err("at most 8 bins a line"),
            }
            n += 1;
        }
        let bins = self.settings.map.bins as u32;
        if start.saturating_add(n as u32) > bins {
            return Err("beyond map.bins");
        }
        self.post(|r| {
            r.map = Some(MapRequest::Write {
                start,
                n: n as u32,
                values,
            })
        })
    }

    fn map_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        let end = start
            .saturating_add(count)
            .min(self.settings.map.bins as u32);
        self.write_chunks(
            (start, end),
            |r, start, max| r.map = Some(MapRequest::Read { start, max }),
            "no position map on this device",
            out,
        )
    }

    fn map_clear(&mut self) -> Result<(), &'static str> {
        if self.settings.map.enable != 0.0 {
            return Err("map.enable is 1: set it to 0 to clear the table");
        }
        self.post(|r| r.map = Some(MapRequest::Clear))
    }

    fn table_status(&mut self) -> protocol::TableStatus {
        protocol::TableStatus(self.has_table.then(|| self.table_report()))
    }

    fn table(&mut self, cmd: TableCmd<'_>, out: &mut dyn Write) -> Result<(), &'static str> {
        self.table_cmd(cmd, out)
    }

    fn frf_off(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.frf = Some(FrfRequest::Stop))
    }

    fn frf_status(&mut self) -> protocol::FrfStatus {
        if let Some(f) = read_frf(&mut self.link) {
            self.frf = f;
        }
        let f = &self.frf;
        protocol::FrfStatus {
            state: f.state,
            measure: f.injection.map(|injection| {
                let chans = [Channel::Command, Channel::Current, Channel::Position];
                // The sine injected is known exactly: its amplitude, in phase, coherent.
                let mut phasors = [[f.amp, 0.0]; 4];
                let mut coherence = [1.0; 4];
                let slots = phasors.iter_mut().zip(coherence.iter_mut()).skip(1);
                for ((ph, coh), ch) in slots.zip(chans) {
                    let p = f.lock.phasor(ch as usize).unwrap_or_default();
                    *ph = [p.re as f32, p.im as f32];
                    *coh = f.lock.coherence(ch as usize).unwrap_or(f64::NAN) as f32;
                }
                protocol::FrfMeasure {
                    injection,
                    f_hz: f.freq_hz as f32,
                    amp: f.amp,
                    groups_done: f.lock.groups(),
                    groups: f.groups,
                    phasors,
                    coherence,
                }
            }),
        }
    }
}
