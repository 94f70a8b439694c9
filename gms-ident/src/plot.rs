//! SVG plots of runs (plotters' SVG backend: no fonts or system libraries needed).

use std::path::Path;

use plotters::prelude::*;

/// A colour of a plot (plotters'), for the series a caller draws.
pub use plotters::style::RGBColor;

use crate::trace::TraceRow;

/// Colours of the feedforward modes: none, static, gms, gms-adaptive.
pub const MODE_COLOURS: [RGBColor; 4] = [
    RGBColor(200, 60, 60),
    RGBColor(230, 150, 20),
    BLUE,
    RGBColor(30, 160, 90),
];

fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-12);
    (lo - pad, hi + pad)
}

/// The series' legend in the chart's corner, on a light background with a frame.
fn legend<'a, DB, X, Y>(c: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    X: Ranged,
    Y: Ranged,
{
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|x| x.to_string())
}

/// What a trace's `friction` column is, for the legend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrictionSource {
    /// A simulated plant's true friction.
    True,
    /// A device's estimate (k_M·i − J·a_ref: what a board can know).
    Estimate,
}

/// One run: reference and position, error in counts, friction and feedforward, over time.
pub fn run_plot(
    path: &Path,
    title: &str,
    trace: &[TraceRow],
    rad_per_count: f64,
    friction: FrictionSource,
) -> Result<(), String> {
    let root = SVGBackend::new(path, (1200, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = root
        .titled(title, ("sans-serif", 22))
        .map_err(|e| e.to_string())?;
    let panels = root.split_evenly((3, 1));
    let t_end = trace.last().map_or(1.0, |r| r.t);
    let e = |msg: &dyn std::fmt::Display| msg.to_string();

    let (lo, hi) = range(
        trace
            .iter()
            .flat_map(|r| [r.reference * 1e3, r.position * 1e3]),
    );
    let mut c = ChartBuilder::on(&panels[0])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .y_desc("position [mrad]")
        .draw()
        .map_err(|x| e(&x))?;
    c.draw_series(LineSeries::new(
        trace.iter().map(|r| (r.t, r.reference * 1e3)),
        BLACK,
    ))
    .map_err(|x| e(&x))?
    .label("reference")
    .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
    c.draw_series(LineSeries::new(
        trace.iter().map(|r| (r.t, r.position * 1e3)),
        BLUE,
    ))
    .map_err(|x| e(&x))?
    .label("encoder")
    .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE));
    legend(&mut c)?;

    let (lo, hi) = range(trace.iter().map(|r| r.error / rad_per_count));
    let mut c = ChartBuilder::on(&panels[1])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .y_desc("error [counts]")
        .draw()
        .map_err(|x| e(&x))?;
    c.draw_series(LineSeries::new(
        trace.iter().map(|r| (r.t, r.error / rad_per_count)),
        RED,
    ))
    .map_err(|x| e(&x))?;

    let (lo, hi) = range(
        trace
            .iter()
            .flat_map(|r| [r.friction * 1e6, r.feedforward * 1e6]),
    );
    let mut c = ChartBuilder::on(&panels[2])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_desc("time [s]")
        .y_desc("torque [uN·m]")
        .draw()
        .map_err(|x| e(&x))?;
    c.draw_series(LineSeries::new(
        trace.iter().map(|r| (r.t, r.friction * 1e6)),
        BLACK,
    ))
    .map_err(|x| e(&x))?
    .label(match friction {
        FrictionSource::True => "true friction (simulated plant)",
        FrictionSource::Estimate => "friction estimate (k_M·i − J·a_ref)",
    })
    .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
    c.draw_series(LineSeries::new(
        trace.iter().map(|r| (r.t, r.feedforward * 1e6)),
        GREEN,
    ))
    .map_err(|x| e(&x))?
    .label("feedforward")
    .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], GREEN));
    legend(&mut c)?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// The error traces of several modes over time, one panel for the whole run and one for the
/// last part (the fine steps), in counts.
pub fn compare_plot(
    path: &Path,
    title: &str,
    traces: &[(&str, &[TraceRow])],
    rad_per_count: f64,
    zoom_from: f64,
) -> Result<(), String> {
    let root = SVGBackend::new(path, (1200, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = root
        .titled(title, ("sans-serif", 22))
        .map_err(|e| e.to_string())?;
    let panels = root.split_evenly((2, 1));
    let e = |msg: &dyn std::fmt::Display| msg.to_string();
    let t_end = traces
        .iter()
        .filter_map(|(_, t)| t.last().map(|r| r.t))
        .fold(1e-9, f64::max);
    for (pi, (from, label)) in [(0.0, "whole run"), (zoom_from, "fine steps")]
        .iter()
        .enumerate()
    {
        let rows = || {
            traces
                .iter()
                .flat_map(|(_, t)| t.iter().filter(|r| r.t >= *from))
        };
        let (lo, hi) = range(rows().map(|r| r.error / rad_per_count));
        let mut c = ChartBuilder::on(&panels[pi])
            .margin(8)
            .caption(*label, ("sans-serif", 16))
            .x_label_area_size(30)
            .y_label_area_size(70)
            .build_cartesian_2d(*from..t_end, lo..hi)
            .map_err(|x| e(&x))?;
        c.configure_mesh()
            .x_desc("time [s]")
            .y_desc("error [counts]")
            .draw()
            .map_err(|x| e(&x))?;
        for (i, (name, t)) in traces.iter().enumerate() {
            let col = MODE_COLOURS[i % MODE_COLOURS.len()];
            c.draw_series(LineSeries::new(
                t.iter()
                    .filter(|r| r.t >= *from)
                    .map(|r| (r.t, r.error / rad_per_count)),
                col,
            ))
            .map_err(|x| e(&x))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col));
        }
        legend(&mut c)?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// Identification plots: data against model. `points` are measured (x, y); `curve` the
/// model sampled densely; axis names with units.
pub fn fit_plot(
    path: &Path,
    title: &str,
    (x_label, y_label): (&str, &str),
    points: &[(f64, f64)],
    curve: &[(f64, f64)],
) -> Result<(), String> {
    let root = SVGBackend::new(path, (900, 650)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let e = |msg: &dyn std::fmt::Display| msg.to_string();
    let (x0, x1) = range(points.iter().chain(curve).map(|p| p.0));
    let (y0, y1) = range(points.iter().chain(curve).map(|p| p.1));
    let mut c = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()
        .map_err(|x| e(&x))?;
    c.draw_series(
        points
            .iter()
            .map(|&(x, y)| Circle::new((x, y), 3, BLUE.filled())),
    )
    .map_err(|x| e(&x))?
    .label("measured")
    .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
    c.draw_series(LineSeries::new(curve.iter().copied(), RED.stroke_width(2)))
        .map_err(|x| e(&x))?
        .label("identified model")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
    legend(&mut c)?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// One curve of a Bode plot: its label, colour, and points `(f [Hz], gain [dB], phase [deg])`;
/// drawn as markers (`points`) or a line.
pub struct BodeSeries<'a> {
    /// The legend's text.
    pub label: &'a str,
    /// Its colour.
    pub colour: RGBColor,
    /// `(f_hz, gain_db, phase_deg)`.
    pub data: &'a [(f64, f64, f64)],
    /// Markers (a measurement) rather than a line (a model).
    pub points: bool,
}

/// A Bode plot: gain \[dB\] over phase \[deg\] against a log frequency axis, `marks` drawn as
/// vertical lines with their labels (crossover, phase crossover).
pub fn bode_plot(
    path: &Path,
    title: &str,
    series: &[BodeSeries<'_>],
    marks: &[(f64, String)],
) -> Result<(), String> {
    let root = SVGBackend::new(path, (900, 750)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let e = |msg: &dyn std::fmt::Display| msg.to_string();
    let root = root.titled(title, ("sans-serif", 20)).map_err(|x| e(&x))?;
    let (top, bottom) = root.split_vertically(380);
    let all = || series.iter().flat_map(|s| s.data.iter());
    let (f0, f1) = {
        let (lo, hi) = all().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
        if lo.is_finite() && hi > lo {
            (lo / 1.1, hi * 1.1)
        } else {
            (1.0, 10.0)
        }
    };
    let panels = [
        (&top, "gain [dB]", 1usize),
        (&bottom, "phase [deg]", 2usize),
    ];
    for (area, label, col) in panels {
        let pick = |p: &(f64, f64, f64)| if col == 1 { p.1 } else { p.2 };
        let (y0, y1) = range(all().map(pick).filter(|v| v.is_finite()));
        let mut c = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((f0..f1).log_scale(), y0..y1)
            .map_err(|x| e(&x))?;
        c.configure_mesh()
            .x_desc("frequency [Hz]")
            .y_desc(label)
            .draw()
            .map_err(|x| e(&x))?;
        for s in series {
            let colour = s.colour;
            let pts = s
                .data
                .iter()
                .filter(|p| pick(p).is_finite())
                .map(|p| (p.0, pick(p)));
            if s.points {
                c.draw_series(pts.map(|q| Circle::new(q, 3, colour.filled())))
                    .map_err(|x| e(&x))?
                    .label(s.label)
                    .legend(move |(x, y)| Circle::new((x + 10, y), 3, colour.filled()));
            } else {
                c.draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                    .map_err(|x| e(&x))?
                    .label(s.label)
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour));
            }
        }
        for (f, text) in marks {
            if *f > f0 && *f < f1 {
                c.draw_series(LineSeries::new(
                    [(*f, y0), (*f, y1)],
                    RGBColor(120, 120, 120).stroke_width(1),
                ))
                .map_err(|x| e(&x))?;
                if col == 1 {
                    c.draw_series(std::iter::once(Text::new(
                        text.clone(),
                        (*f, y1 - 0.08 * (y1 - y0)),
                        ("sans-serif", 13),
                    )))
                    .map_err(|x| e(&x))?;
                }
            }
        }
        if col == 1 {
            c.configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .position(SeriesLabelPosition::LowerLeft)
                .draw()
                .map_err(|x| e(&x))?;
        }
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// Learning from repetition: the top panel each iteration's RMS and peak error \[counts\]
/// (`iterations`: `(iteration, rms, peak)`), the bottom the error over the period \[counts\]
/// against time \[s\] for the labelled passes in `errors` (e.g. the first and the last).
pub fn learn_plot(
    path: &Path,
    title: &str,
    iterations: &[(f64, f64, f64)],
    errors: &[(&str, &[(f64, f64)])],
) -> Result<(), String> {
    let root = SVGBackend::new(path, (1100, 850)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = root
        .titled(title, ("sans-serif", 22))
        .map_err(|e| e.to_string())?;
    let panels = root.split_evenly((2, 1));
    let e = |msg: &dyn std::fmt::Display| msg.to_string();
    let (x0, x1) = range(iterations.iter().map(|r| r.0));
    let (_, y1) = range(iterations.iter().flat_map(|r| [r.1, r.2]));
    let mut c = ChartBuilder::on(&panels[0])
        .margin(8)
        .caption("the error per iteration", ("sans-serif", 16))
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, 0.0..y1.max(1e-9))
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_desc("iteration")
        .y_desc("error [counts]")
        .draw()
        .map_err(|x| e(&x))?;
    for (k, (name, col)) in [("RMS", BLUE), ("peak", RED)].into_iter().enumerate() {
        let pts: Vec<(f64, f64)> = iterations
            .iter()
            .map(|r| (r.0, if k == 0 { r.1 } else { r.2 }))
            .collect();
        c.draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
            .map_err(|x| e(&x))?
            .label(name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col));
        c.draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled())))
            .map_err(|x| e(&x))?;
    }
    legend(&mut c)?;
    let (t0, t1) = range(errors.iter().flat_map(|(_, v)| v.iter().map(|p| p.0)));
    let (lo, hi) = range(errors.iter().flat_map(|(_, v)| v.iter().map(|p| p.1)));
    let mut c = ChartBuilder::on(&panels[1])
        .margin(8)
        .caption("the error over the period", ("sans-serif", 16))
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(t0..t1, lo..hi)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_desc("time in the period [s]")
        .y_desc("error [counts]")
        .draw()
        .map_err(|x| e(&x))?;
    for (i, (name, v)) in errors.iter().enumerate() {
        let col = MODE_COLOURS[i % MODE_COLOURS.len()];
        c.draw_series(LineSeries::new(v.iter().copied(), col))
            .map_err(|x| e(&x))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col));
    }
    legend(&mut c)?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
