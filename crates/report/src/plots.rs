//! PNG plots of a run in the spirit of the paper's Figs. 3–7 (plotters, bitmap
//! backend, text rendered with the bundled DejaVu Sans through `ab_glyph`, so no
//! system font library is needed at run time).
//!
//! - `errors.png`: task errors per level (Figs. 3 and 6),
//! - `torques.png`: applied torque and the contribution of each level and of τ_μ (Fig. 4),
//! - `disturbing_accelerations.png`: ‖J_i M⁻¹ τ_j‖ per level i (Fig. 5),
//! - `disturbing_accelerations_v.png`: ‖J̄_i M⁻¹ τ_j‖, the same in the local
//!   null-space velocities (zero up to rounding when the levels are decoupled),
//! - `energies.png`: level energies S_i with their kinetic/potential split (Fig. 7),
//! - `joints.png`: joint positions and velocities.
//!
//! A plot whose columns are missing from the trajectory is skipped.

use crate::columns;
use crate::{Metrics, ReportError, Trajectory};
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

pub(crate) const FONT_FAMILY: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Registers the bundled font with plotters once per process.
pub(crate) fn ensure_font() -> Result<(), ReportError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT_BYTES).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(ReportError::Plot {
            path: PathBuf::from("assets/DejaVuSans.ttf"),
            message: "the bundled font could not be loaded".into(),
        })
    }
}

/// One line of a panel.
struct Series {
    label: String,
    values: Vec<f64>,
}

/// One sub-plot.
struct Panel {
    title: String,
    y_label: String,
    series: Vec<Series>,
}

pub(crate) const COLORS: [RGBColor; 8] = [
    RGBColor(0, 90, 181),
    RGBColor(220, 50, 32),
    RGBColor(0, 140, 60),
    RGBColor(230, 140, 0),
    RGBColor(120, 60, 170),
    RGBColor(0, 160, 170),
    RGBColor(150, 90, 40),
    RGBColor(90, 90, 90),
];

fn y_range(series: &[Series]) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in series {
        for &v in &s.values {
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    let scale = lo.abs().max(hi.abs());
    if span <= 1e-12 * scale.max(1e-300) {
        let pad = if scale > 0.0 { 0.1 * scale } else { 1.0 };
        return (lo - pad, hi + pad);
    }
    (lo - 0.06 * span, hi + 0.06 * span)
}

fn tick_label(v: f64, span: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !(1e-3..1e5).contains(&span) {
        format!("{v:.1e}")
    } else if span < 0.1 {
        format!("{v:.4}")
    } else if span < 10.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.0}")
    }
}

pub(crate) fn draw_err<E: std::fmt::Debug>(path: &Path) -> impl Fn(E) -> ReportError + '_ {
    move |e| ReportError::Plot {
        path: path.to_path_buf(),
        message: format!("{e:?}"),
    }
}

/// Draws stacked panels over a shared time axis into `path`.
fn draw_panels(path: &Path, title: &str, t: &[f64], panels: &[Panel]) -> Result<(), ReportError> {
    ensure_font()?;
    let height = 60 + 280 * panels.len() as u32;
    let root = BitMapBackend::new(path, (1200, height)).into_drawing_area();
    let err = draw_err(path);
    root.fill(&WHITE).map_err(&err)?;
    let root = root
        .titled(title, (FONT_FAMILY, 26).into_font())
        .map_err(&err)?;
    let areas = root.split_evenly((panels.len(), 1));
    let t0 = t.first().copied().unwrap_or(0.0);
    let t1 = t.last().copied().unwrap_or(1.0).max(t0 + 1e-9);
    for (area, panel) in areas.iter().zip(panels) {
        let (lo, hi) = y_range(&panel.series);
        let span = hi - lo;
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, (FONT_FAMILY, 20).into_font())
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(90)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc(panel.y_label.as_str())
            .label_style((FONT_FAMILY, 15).into_font())
            .axis_desc_style((FONT_FAMILY, 16).into_font())
            .y_label_formatter(&|v| tick_label(*v, span))
            .x_label_formatter(&|v| format!("{v:.2}"))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(&err)?;
        for (k, s) in panel.series.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    t.iter()
                        .zip(&s.values)
                        .filter(|(_, v)| v.is_finite())
                        .map(|(a, b)| (*a, *b)),
                    color.stroke_width(2),
                ))
                .map_err(&err)?
                .label(s.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .label_font((FONT_FAMILY, 15).into_font())
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(&err)?;
    }
    root.present().map_err(&err)?;
    Ok(())
}

fn series(traj: &Trajectory, name: &str, label: String) -> Option<Series> {
    traj.column(name).map(|values| Series { label, values })
}

/// Writes every plot that the trajectory's columns allow into `dir`; returns the files written.
pub fn plot_all(
    dir: &Path,
    traj: &Trajectory,
    metrics: &Metrics,
) -> Result<Vec<PathBuf>, ReportError> {
    let t = traj.require(columns::TIME)?;
    let run = &metrics.run;
    let n = run.n_joints;
    let r = run.levels.len();
    let scenario = &run.scenario;
    let mut written = Vec::new();

    // Errors per level (Figs. 3/6).
    let panels: Vec<Panel> = run
        .levels
        .iter()
        .enumerate()
        .map(|(i, l)| Panel {
            title: format!("Level {}: {}", i + 1, l.name),
            y_label: format!("error [{}]", l.unit_label()),
            series: (1..=l.dim)
                .filter_map(|k| series(traj, &columns::error(i + 1, k), format!("e{}_{k}", i + 1)))
                .collect(),
        })
        .collect();
    if r > 0 {
        let p = dir.join("errors.png");
        draw_panels(
            &p,
            &format!("{scenario}: task errors x_i - x_i,d"),
            &t,
            &panels,
        )?;
        written.push(p);
    }

    // Torques: applied, per level, tau_mu (Fig. 4).
    let mut panels = vec![Panel {
        title: "Applied torque (gravity included)".into(),
        y_label: "tau [Nm]".into(),
        series: (1..=n)
            .filter_map(|k| series(traj, &columns::torque(k), format!("joint {k}")))
            .collect(),
    }];
    for i in 1..=r {
        let s: Vec<Series> = (1..=n)
            .filter_map(|k| series(traj, &columns::level_torque(i, k), format!("joint {k}")))
            .collect();
        if !s.is_empty() {
            panels.push(Panel {
                title: format!("Level {i} torque tau_{i}"),
                y_label: format!("tau_{i} [Nm]"),
                series: s,
            });
        }
    }
    let s: Vec<Series> = (1..=n)
        .filter_map(|k| series(traj, &columns::mu_torque(k), format!("joint {k}")))
        .collect();
    if !s.is_empty() {
        panels.push(Panel {
            title: "Coriolis cancellation tau_mu".into(),
            y_label: "tau_mu [Nm]".into(),
            series: s,
        });
    }
    let p = dir.join("torques.png");
    draw_panels(&p, &format!("{scenario}: control torques"), &t, &panels)?;
    written.push(p);

    // Disturbing accelerations (Fig. 5).
    let mut panels = Vec::new();
    for i in 1..=r {
        let mut s: Vec<Series> = (1..=r)
            .filter(|&j| j != i)
            .filter_map(|j| {
                series(
                    traj,
                    &columns::disturbing_acceleration(i, j),
                    format!("from level {j}"),
                )
            })
            .collect();
        s.extend(series(
            traj,
            &columns::mu_acceleration(i),
            "from tau_mu (cancellation)".into(),
        ));
        if !s.is_empty() {
            let unit = match run.levels[i - 1].unit_label().as_str() {
                "" => String::new(),
                u => format!(" [{u}/s^2]"),
            };
            panels.push(Panel {
                title: format!(
                    "Level {i}: |J_{i} M^-1 tau_j| (acceleration caused by other levels)"
                ),
                y_label: format!("accel.{unit}"),
                series: s,
            });
        }
    }
    if !panels.is_empty() {
        let p = dir.join("disturbing_accelerations.png");
        draw_panels(
            &p,
            &format!("{scenario}: disturbing accelerations"),
            &t,
            &panels,
        )?;
        written.push(p);
    }

    // The same in the local null-space velocities v_i (decoupling of Sec. III).
    let mut panels = Vec::new();
    for i in 1..=r {
        let s: Vec<Series> = (1..=r)
            .filter(|&j| j != i)
            .filter_map(|j| {
                series(
                    traj,
                    &columns::null_space_acceleration(i, j),
                    format!("from level {j}"),
                )
            })
            .collect();
        if !s.is_empty() {
            panels.push(Panel {
                title: format!(
                    "Level {i}: |Jbar_{i} M^-1 tau_j| (dv_{i}/dt caused by other levels)"
                ),
                y_label: "accel.".into(),
                series: s,
            });
        }
    }
    if !panels.is_empty() {
        let p = dir.join("disturbing_accelerations_v.png");
        draw_panels(
            &p,
            &format!("{scenario}: disturbing accelerations in null-space coordinates"),
            &t,
            &panels,
        )?;
        written.push(p);
    }

    // Energies (Fig. 7).
    let mut panels = Vec::new();
    for i in 1..=r {
        let mut s = Vec::new();
        s.extend(series(traj, &columns::energy(i), format!("S_{i} total")));
        s.extend(series(traj, &columns::energy_kinetic(i), "kinetic".into()));
        s.extend(series(
            traj,
            &columns::energy_potential(i),
            "potential".into(),
        ));
        if !s.is_empty() {
            panels.push(Panel {
                title: format!("Level {i}: energy S_{i}"),
                y_label: "energy [J]".into(),
                series: s,
            });
        }
    }
    if !panels.is_empty() {
        let p = dir.join("energies.png");
        draw_panels(&p, &format!("{scenario}: level energies"), &t, &panels)?;
        written.push(p);
    }

    // Joint positions and velocities.
    let panels = vec![
        Panel {
            title: "Joint positions".into(),
            y_label: "q [rad]".into(),
            series: (1..=n)
                .filter_map(|k| series(traj, &columns::position(k), format!("q{k}")))
                .collect(),
        },
        Panel {
            title: "Joint velocities".into(),
            y_label: "qd [rad/s]".into(),
            series: (1..=n)
                .filter_map(|k| series(traj, &columns::velocity(k), format!("qd{k}")))
                .collect(),
        },
    ];
    let p = dir.join("joints.png");
    draw_panels(&p, &format!("{scenario}: joint state"), &t, &panels)?;
    written.push(p);

    Ok(written)
}
