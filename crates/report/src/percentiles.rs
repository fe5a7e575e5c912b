//! Latency-versus-percentile plots (HdrHistogram's percentile distribution):
//! the x axis is the percentile on the 1 / (1 − p) scale — 90 %, 99 %, 99.9 %,
//! … evenly spaced — and the y axis the latency on a log scale, so the tail
//! that decides a real-time loop is as visible as the median.

use std::path::Path;

use plotters::prelude::*;

use crate::ReportError;
use crate::plots::{COLORS, FONT_FAMILY, draw_err, ensure_font};

/// Highest percentile the x axis can show (99.9999 %).
const X_NINES: f64 = 6.0;

/// One latency distribution of the plot.
#[derive(Clone, Debug, PartialEq)]
pub struct PercentileCurve {
    /// Legend text.
    pub label: String,
    /// (percentile 0…100, latency µs), percentile increasing.
    pub points: Vec<(f64, f64)>,
    /// Draw as a reference (thin dashed line), e.g. the machine's floor.
    pub reference: bool,
    /// Colour index; a reference usually shares the colour of what it is the reference of.
    pub color: usize,
}

/// x coordinate of a percentile: the number of nines, log10(1 / (1 − p)).
fn nines(percentile: f64) -> f64 {
    let rest = 1.0 - percentile / 100.0;
    if rest <= 10f64.powf(-X_NINES) {
        X_NINES
    } else {
        -rest.log10()
    }
}

fn percentile_label(x: f64) -> String {
    let k = x.round() as i32;
    if (x - k as f64).abs() > 1e-6 {
        return String::new();
    }
    match k {
        0 => "0 %".into(),
        1 => "90 %".into(),
        k => format!("{:.*} %", (k - 2) as usize, 100.0 - 10f64.powi(2 - k)),
    }
}

/// Draws the curves into `path` (PNG, 1200×700).
pub fn plot_percentiles(
    path: &Path,
    title: &str,
    curves: &[PercentileCurve],
) -> Result<(), ReportError> {
    ensure_font()?;
    let err = draw_err(path);
    let mut lo = f64::INFINITY;
    let mut hi: f64 = 0.0;
    let mut x_hi: f64 = 1.0;
    for c in curves {
        for &(p, v) in &c.points {
            if v.is_finite() && v > 0.0 {
                lo = lo.min(v);
                hi = hi.max(v);
            }
            if p < 100.0 {
                x_hi = x_hi.max(nines(p));
            }
        }
    }
    if !lo.is_finite() {
        lo = 0.1;
        hi = 1.0;
    }
    let (lo, hi) = (lo / 1.5, (hi * 1.5).max(lo * 10.0));
    // The axis ends at the next whole number of nines; a curve's 100 % point
    // (its maximum) is drawn there.
    let x_hi = x_hi.ceil().min(X_NINES);
    let x_of = |p: f64| nines(p).min(x_hi);

    let root = BitMapBackend::new(path, (1200, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT_FAMILY, 24).into_font())
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..x_hi, (lo..hi).log_scale())
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc("percentile")
        .y_desc("latency [µs]")
        .x_labels((x_hi as usize) + 1)
        .x_label_formatter(&|x| percentile_label(*x))
        .y_label_formatter(&|v| {
            if *v >= 10.0 {
                format!("{v:.0}")
            } else if *v >= 1.0 {
                format!("{v:.1}")
            } else {
                format!("{v:.2}")
            }
        })
        .label_style((FONT_FAMILY, 15).into_font())
        .axis_desc_style((FONT_FAMILY, 16).into_font())
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(&err)?;
    for c in curves {
        let color = COLORS[c.color % COLORS.len()];
        let style = if c.reference {
            color.mix(0.7).stroke_width(1)
        } else {
            color.stroke_width(3)
        };
        let points: Vec<(f64, f64)> = c
            .points
            .iter()
            .filter(|(_, v)| v.is_finite() && *v > 0.0)
            .map(|&(p, v)| (x_of(p), v))
            .collect();
        if c.reference {
            chart
                .draw_series(DashedLineSeries::new(points, 8, 5, style))
                .map_err(&err)?
                .label(c.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        } else {
            chart
                .draw_series(LineSeries::new(points, style))
                .map_err(&err)?
                .label(c.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
    }
    chart
        .configure_series_labels()
        .label_font((FONT_FAMILY, 15).into_font())
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(&err)?;
    root.present().map_err(&err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_axis() {
        assert_eq!(nines(0.0), 0.0);
        assert!((nines(90.0) - 1.0).abs() < 1e-12);
        assert!((nines(99.9) - 3.0).abs() < 1e-9);
        assert_eq!(nines(100.0), X_NINES);
        assert_eq!(percentile_label(0.0), "0 %");
        assert_eq!(percentile_label(1.0), "90 %");
        assert_eq!(percentile_label(2.0), "99 %");
        assert_eq!(percentile_label(3.0), "99.9 %");
        assert_eq!(percentile_label(5.0), "99.999 %");
        assert_eq!(percentile_label(2.5), "");
    }

    #[test]
    fn draws_a_png() {
        let dir = std::env::temp_dir().join(format!("hcc-pct-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.png");
        let curve = |label: &str, reference: bool, scale: f64| PercentileCurve {
            label: label.into(),
            points: (0..40)
                .map(|k| {
                    let p = 100.0 * (1.0 - 0.5f64.powi(k / 4));
                    (p, scale * (1.0 + k as f64))
                })
                .chain([(100.0, scale * 100.0)])
                .collect(),
            reference,
            color: 0,
        };
        plot_percentiles(
            &path,
            "test",
            &[curve("measured", false, 2.0), curve("floor", true, 1.0)],
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"\x89PNG"));
        // An empty plot is still a valid file.
        plot_percentiles(&path, "empty", &[]).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
