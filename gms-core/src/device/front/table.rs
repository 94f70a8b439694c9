//! The table motion's requests (`table …`): the reference and correction written in pieces and
//! checked, the geometry set, runs, reads of the tables and the period's error.

use super::*;

impl<L: LoopLink, S: ParamStore> Front<L, S> {
    /// The table motion's last report.
    pub(super) fn table_report(&mut self) -> TableReport {
        self.link.with_mailbox(|m| m.table)
    }

    /// `table …` (every form but the status): acts on the table motion.
    pub(super) fn table_cmd(
        &mut self,
        cmd: TableCmd<'_>,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        if !self.has_table {
            return Err("no table motion on this device");
        }
        let t = self.table_report();
        let playing = t.state == TableState::Playing;
        let reason = |e: TableError| e.reason();
        match cmd {
            TableCmd::Status => Ok(()),
            TableCmd::Write {
                which,
                start,
                values,
            } => {
                let mut v = [0.0f32; TABLE_WRITE_VALUES];
                let mut n = 0usize;
                for w in values.split_ascii_whitespace() {
                    let x = protocol::parse_f32(w).ok_or("a value is a number")?;
                    *v.get_mut(n).ok_or("at most 8 values a line")? = x;
                    n += 1;
                }
                let vals = v.get(..n).unwrap_or(&[]);
                let mut u = self.upload;
                match which {
                    Which::Ref => {
                        if playing {
                            return Err("playing (table stop first)");
                        }
                        u.write_ref(start, vals).map_err(reason)?;
                        // The loop drops its correction with the reference.
                        u.corr_next = 0;
                    }
                    _ => {
                        let g = t.geometry.ok_or("no table set (table set first)")?;
                        if t.pending {
                            return Err("a correction waits for the next period's start");
                        }
                        let torque = self.settings.motor.k_m * self.settings.i_max;
                        u.write_corr(start, vals, g.points, torque)
                            .map_err(|e| match e {
                                TableError::BadValue => {
                                    "a value not finite or beyond the drive's torque (k_m × i_max)"
                                }
                                e => e.reason(),
                            })?;
                    }
                }
                self.post(|r| {
                    r.table = Some(TableRequest::Write {
                        which,
                        start,
                        n: n as u32,
                        values: v,
                    })
                })?;
                self.upload = u;
                Ok(())
            }
            TableCmd::Set(g) => {
                if playing {
                    return Err("playing (table stop first)");
                }
                let limits = self.board.limits(&self.settings);
                self.upload
                    .check_set(
                        &g,
                        self.settings.pos_rate_hz,
                        self.settings.rad_per_count(),
                        crate::control::reference::VELOCITY_MAX,
                        (limits.pos_min, limits.pos_max),
                    )
                    .map_err(reason)?;
                self.post(|r| r.table = Some(TableRequest::Set(g)))?;
                self.upload.corr_next = 0;
                Ok(())
            }
            TableCmd::Use => {
                let g = t.geometry.ok_or("no table set (table set first)")?;
                if t.pending {
                    return Err("a correction waits for the next period's start");
                }
                if self.upload.corr_next != g.points {
                    return Err("the correction is not written whole (POINTS values from 0)");
                }
                self.post(|r| r.table = Some(TableRequest::Use))?;
                self.upload.corr_next = 0;
                Ok(())
            }
            TableCmd::CorrOff => self.post(|r| r.table = Some(TableRequest::NoCorrection)),
            TableCmd::Run(n) => {
                let g = match t.state {
                    TableState::Empty => return Err("no table set (table set first)"),
                    TableState::Playing => return Err("already playing"),
                    TableState::Ready => t.geometry.ok_or("no table set (table set first)")?,
                };
                let st = self.status_now();
                if !st.enabled {
                    return Err("disabled (enable first)");
                }
                if st.drive != Drive::Position || st.moving {
                    return Err("the axis is not holding a position (hold first)");
                }
                let start = self.upload.start(g.origin);
                if (st.reference.pos.saturating_sub(start)).unsigned_abs() > SUB_PER_COUNT as u64 {
                    return Err("the reference is not at the table's start (move there first)");
                }
                self.post(|r| r.table = Some(TableRequest::Run(n)))?;
                if self.table_report().state != TableState::Playing {
                    return Err("the control loop did not start the table");
                }
                Ok(())
            }
            TableCmd::Stop => self.post(|r| r.table = Some(TableRequest::Stop)),
            TableCmd::Next => self.post(|r| r.table = Some(TableRequest::Next)),
            TableCmd::Read {
                which,
                start,
                count,
            } => {
                let points = t.geometry.map_or(0, |g| g.points);
                match which {
                    Which::Corr if t.generation == 0 => return Err("no correction played"),
                    Which::Err if t.done.is_none() => return Err("no period complete yet"),
                    _ => {}
                }
                if points == 0 {
                    return Err("no table set (table set first)");
                }
                let end = start.saturating_add(count).min(points);
                self.write_chunks(
                    (start, end),
                    |r, start, max| r.table = Some(TableRequest::Read { which, start, max }),
                    "no table to read",
                    out,
                )?;
                if which == Which::Err && self.table_report().done != t.done {
                    return Err(crate::control::table::READ_RACED);
                }
                Ok(())
            }
            TableCmd::Clear => {
                if playing {
                    return Err("playing (table stop first)");
                }
                self.post(|r| r.table = Some(TableRequest::Clear))?;
                self.upload = Upload::default();
                Ok(())
            }
        }
    }
}
