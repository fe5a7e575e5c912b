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
use crate::{Metrics, ReportError, RunDescription, Trajectory};
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
    // The range of the finite times (not the first and last: a plot must
    // never map a point far outside its area, whatever the data).
    let finite = || t.iter().copied().filter(|v| v.is_finite());
    let t0 = finite().fold(f64::INFINITY, f64::min);
    let t0 = if t0.is_finite() { t0 } else { 0.0 };
    let t1 = finite().fold(f64::NEG_INFINITY, f64::max).max(t0 + 1e-9);
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
                        .filter(|(a, v)| a.is_finite() && v.is_finite())
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

/// One panel of [`plot_time_series`]: a title, the y axis label and the
/// (label, values) of its lines, one value per time sample.
#[derive(Clone, Debug, PartialEq)]
pub struct TimePanel {
    pub title: String,
    pub y_label: String,
    pub series: Vec<(String, Vec<f64>)>,
}

/// Draws stacked `panels` over the time axis `t` into `path` (PNG, 1200 wide,
/// 280 per panel), in the style of the run plots; non-finite values are skipped.
pub fn plot_time_series(
    path: &Path,
    title: &str,
    t: &[f64],
    panels: &[TimePanel],
) -> Result<(), ReportError> {
    let panels: Vec<Panel> = panels
        .iter()
        .map(|p| Panel {
            title: p.title.clone(),
            y_label: p.y_label.clone(),
            series: p
                .series
                .iter()
                .map(|(label, values)| Series {
                    label: label.clone(),
                    values: values.clone(),
                })
                .collect(),
        })
        .collect();
    draw_panels(path, title, t, &panels)
}

/// The plot context: the run's table, its time column and description.
struct Plotter<'a> {
    dir: &'a Path,
    traj: &'a Trajectory,
    t: Vec<f64>,
    run: &'a RunDescription,
}

impl Plotter<'_> {
    fn series(&self, name: &str, label: String) -> Option<Series> {
        self.traj
            .column(name)
            .map(|values| Series { label, values })
    }

    /// The joint series of column `name(k)` for k = 1..n, labelled `label(k)`.
    fn joints(&self, name: fn(usize) -> String, label: impl Fn(usize) -> String) -> Vec<Series> {
        (1..=self.run.n_joints)
            .filter_map(|k| self.series(&name(k), label(k)))
            .collect()
    }

    /// Draws `panels` into `file` unless there are none; the file written.
    fn draw(
        &self,
        file: &str,
        title: &str,
        panels: &[Panel],
    ) -> Result<Option<PathBuf>, ReportError> {
        if panels.is_empty() {
            return Ok(None);
        }
        let p = self.dir.join(file);
        draw_panels(
            &p,
            &format!("{}: {title}", self.run.scenario),
            &self.t,
            panels,
        )?;
        Ok(Some(p))
    }

    /// Task errors per level (Figs. 3/6).
    fn errors(&self) -> Result<Option<PathBuf>, ReportError> {
        let panels: Vec<Panel> = self
            .run
            .levels
            .iter()
            .enumerate()
            .map(|(i, l)| Panel {
                title: format!("Level {}: {}", i + 1, l.name),
                y_label: format!("error [{}]", l.unit_label()),
                series: (1..=l.dim)
                    .filter_map(|k| {
                        self.series(&columns::error(i + 1, k), format!("e{}_{k}", i + 1))
                    })
                    .collect(),
            })
            .collect();
        self.draw("errors.png", "task errors x_i - x_i,d", &panels)
    }

    /// Torques: applied, per level, τ_μ (Fig. 4).
    fn torques(&self) -> Result<Option<PathBuf>, ReportError> {
        let mut panels = vec![Panel {
            title: "Applied torque (gravity included)".into(),
            y_label: "tau [Nm]".into(),
            series: self.joints(columns::torque, |k| format!("joint {k}")),
        }];
        for i in 1..=self.run.levels.len() {
            let s: Vec<Series> = (1..=self.run.n_joints)
                .filter_map(|k| self.series(&columns::level_torque(i, k), format!("joint {k}")))
                .collect();
            if !s.is_empty() {
                panels.push(Panel {
                    title: format!("Level {i} torque tau_{i}"),
                    y_label: format!("tau_{i} [Nm]"),
                    series: s,
                });
            }
        }
        let s = self.joints(columns::mu_torque, |k| format!("joint {k}"));
        if !s.is_empty() {
            panels.push(Panel {
                title: "Coriolis cancellation tau_mu".into(),
                y_label: "tau_mu [Nm]".into(),
                series: s,
            });
        }
        self.draw("torques.png", "control torques", &panels)
    }

    /// The series of level `i` caused by the other levels, `column(i, j)`.
    fn caused_by_other_levels(&self, i: usize, column: fn(usize, usize) -> String) -> Vec<Series> {
        (1..=self.run.levels.len())
            .filter(|&j| j != i)
            .filter_map(|j| self.series(&column(i, j), format!("from level {j}")))
            .collect()
    }

    /// Disturbing accelerations ‖J_i M⁻¹ τ_j‖ (Fig. 5).
    fn disturbing_accelerations(&self) -> Result<Option<PathBuf>, ReportError> {
        let mut panels = Vec::new();
        for i in 1..=self.run.levels.len() {
            let mut s = self.caused_by_other_levels(i, columns::disturbing_acceleration);
            s.extend(self.series(
                &columns::mu_acceleration(i),
                "from tau_mu (cancellation)".into(),
            ));
            if !s.is_empty() {
                let unit = match self.run.levels[i - 1].unit_label().as_str() {
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
        self.draw(
            "disturbing_accelerations.png",
            "disturbing accelerations",
            &panels,
        )
    }

    /// The same in the local null-space velocities v_i (decoupling of Sec. III).
    fn null_space_accelerations(&self) -> Result<Option<PathBuf>, ReportError> {
        let mut panels = Vec::new();
        for i in 1..=self.run.levels.len() {
            let s = self.caused_by_other_levels(i, columns::null_space_acceleration);
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
        self.draw(
            "disturbing_accelerations_v.png",
            "disturbing accelerations in null-space coordinates",
            &panels,
        )
    }

    /// Level energies S_i and their kinetic/potential split (Fig. 7).
    fn energies(&self) -> Result<Option<PathBuf>, ReportError> {
        let mut panels = Vec::new();
        for i in 1..=self.run.levels.len() {
            let mut s = Vec::new();
            s.extend(self.series(&columns::energy(i), format!("S_{i} total")));
            s.extend(self.series(&columns::energy_kinetic(i), "kinetic".into()));
            s.extend(self.series(&columns::energy_potential(i), "potential".into()));
            if !s.is_empty() {
                panels.push(Panel {
                    title: format!("Level {i}: energy S_{i}"),
                    y_label: "energy [J]".into(),
                    series: s,
                });
            }
        }
        self.draw("energies.png", "level energies", &panels)
    }

    /// Joint positions and velocities.
    fn joint_state(&self) -> Result<Option<PathBuf>, ReportError> {
        let panels = [
            Panel {
                title: "Joint positions".into(),
                y_label: "q [rad]".into(),
                series: self.joints(columns::position, |k| format!("q{k}")),
            },
            Panel {
                title: "Joint velocities".into(),
                y_label: "qd [rad/s]".into(),
                series: self.joints(columns::velocity, |k| format!("qd{k}")),
            },
        ];
        self.draw("joints.png", "joint state", &panels)
    }
}

/// Writes every plot that the trajectory's columns allow into `dir`; returns the files written.
pub fn plot_all(
    dir: &Path,
    traj: &Trajectory,
    metrics: &Metrics,
) -> Result<Vec<PathBuf>, ReportError> {
    let plotter = Plotter {
        dir,
        traj,
        t: traj.require(columns::TIME)?,
        run: &metrics.run,
    };
    let mut written = Vec::new();
    if !plotter.run.levels.is_empty() {
        written.extend(plotter.errors()?);
    }
    written.extend(plotter.torques()?);
    written.extend(plotter.disturbing_accelerations()?);
    written.extend(plotter.null_space_accelerations()?);
    written.extend(plotter.energies()?);
    written.extend(plotter.joint_state()?);
    Ok(written)
}
