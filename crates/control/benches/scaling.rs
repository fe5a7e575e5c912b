//! Controller step time against the number of joints: synthetic serial chains of 4, 7,
//! 12, 20 and 32 revolute joints (axes alternating z / y, tapering links of realistic
//! mass and inertia, 1.1 m reach) with 3–4 priority levels:
//!
//! | n | levels |
//! | --- | --- |
//! | 4 | TCP position x, z (2) / joint 1 (1) / posture (4) |
//! | 7 | TCP position (3) / TCP orientation (3) / posture (7) |
//! | 12, 20, 32 | TCP position (3) / TCP orientation (3) / every 4th joint (3, 5, 8) / posture (n) |
//!
//! Prints median, p99, p99.9 and max per size and writes a log-log plot of the time
//! against n with n² and n³ reference lines, plus the table as CSV, to
//! `<target dir>/hcc-bench/` (the path is printed).
//! `cargo bench -p hcc-control --bench scaling` (`-- 32` for one size).

mod support;
use hcc_control::{ControllerSpec, LevelSpec, TaskSpec};
use hcc_model::Model;
use nalgebra::{DMatrix, DVector};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;

const SIZES: [usize; 5] = [4, 7, 12, 20, 32];
const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../report/assets/DejaVuSans.ttf");

/// URDF of an n-joint chain: a 0.1 m base, then n links of length 1 / n along their z
/// axis, joint k about z (k even) or y (k odd). Link k is a cylinder tapering from
/// r = 6 cm to 3 cm with its mass falling linearly from 1.5 to 0.5 of 16 kg / n
/// (about 16 kg in all), centre of mass at the middle.
fn chain_urdf(n: usize) -> String {
    let len = 1.0 / n as f64;
    let mut s = String::new();
    writeln!(s, "<?xml version=\"1.0\"?>\n<robot name=\"chain{n}\">").unwrap();
    writeln!(s, "  <link name=\"base\"/>").unwrap();
    for k in 0..n {
        let f = k as f64 / (n - 1) as f64;
        let m = 16.0 / n as f64 * (1.5 - f);
        let r = 0.06 - 0.03 * f;
        let ixx = m * (3.0 * r * r + len * len) / 12.0;
        let izz = 0.5 * m * r * r;
        writeln!(
            s,
            "  <link name=\"link{k}\"><inertial><origin xyz=\"0 0 {c}\"/><mass value=\"{m}\"/>\
             <inertia ixx=\"{ixx}\" ixy=\"0\" ixz=\"0\" iyy=\"{ixx}\" iyz=\"0\" izz=\"{izz}\"/>\
             </inertial></link>",
            c = 0.5 * len
        )
        .unwrap();
        let parent = if k == 0 {
            "base".to_string()
        } else {
            format!("link{}", k - 1)
        };
        let z = if k == 0 { 0.1 } else { len };
        let axis = if k % 2 == 0 { "0 0 1" } else { "0 1 0" };
        writeln!(
            s,
            "  <joint name=\"j{k}\" type=\"revolute\"><parent link=\"{parent}\"/>\
             <child link=\"link{k}\"/><origin xyz=\"0 0 {z}\"/><axis xyz=\"{axis}\"/>\
             <limit lower=\"-2.9\" upper=\"2.9\" effort=\"100\" velocity=\"2\"/></joint>"
        )
        .unwrap();
    }
    writeln!(
        s,
        "  <link name=\"tcp\"/>\n  <joint name=\"tcp_joint\" type=\"fixed\">\
         <parent link=\"link{}\"/><child link=\"tcp\"/><origin xyz=\"0 0 {len}\"/></joint>\n</robot>",
        n - 1
    )
    .unwrap();
    s
}

/// Start configuration: the y joints bend the chain by about 2 rad in all, the z joints
/// twist it by up to ±0.6 rad in all (a curved, twisted arm away from singularities).
fn start_configuration(n: usize) -> Vec<f64> {
    let half = (n / 2) as f64;
    (0..n)
        .map(|k| {
            let x = k as f64;
            if k % 2 == 1 {
                2.0 / half * (1.0 + 0.3 * (1.7 * x).cos())
            } else {
                0.6 / half * (1.3 * x + 0.4).sin()
            }
        })
        .collect()
}

fn diag(n: usize, v: f64) -> DMatrix<f64> {
    DMatrix::from_diagonal_element(n, n, v)
}

/// The hierarchy of the table in the module docs, goals a few cm / a few 0.1 rad away
/// from the start.
fn chain_spec(model: &Model, q0: &[f64]) -> ControllerSpec {
    let n = model.nq();
    let tcp = model.frame_id("tcp").expect("tcp frame");
    let mut data = hcc_model::Data::new(model);
    hcc_model::forward_kinematics(model, &mut data, &DVector::from_column_slice(q0));
    let pose = hcc_model::frame_placement(model, &data, tcp);
    let p = pose.translation.vector;
    let (roll, pitch, yaw) = pose.rotation.euler_angles();
    let position = |axes: Vec<usize>| {
        let goal = axes
            .iter()
            .map(|&a| p[a] + [0.05, -0.03, 0.04][a])
            .collect();
        let m = axes.len();
        LevelSpec {
            name: "tcp position".into(),
            task: TaskSpec::Position { frame: tcp, axes },
            stiffness: diag(m, 800.0),
            damping: diag(m, 60.0),
            goal: DVector::from_vec(goal),
        }
    };
    let joints = |indices: Vec<usize>| {
        let m = indices.len();
        let goal = indices.iter().map(|&k| q0[k] + 0.1).collect();
        LevelSpec {
            name: "joints".into(),
            task: TaskSpec::Joints { indices },
            stiffness: diag(m, 50.0),
            damping: diag(m, 5.0),
            goal: DVector::from_vec(goal),
        }
    };
    let posture = LevelSpec {
        name: "posture".into(),
        task: TaskSpec::Posture,
        stiffness: diag(n, 20.0),
        damping: diag(n, 2.0),
        goal: DVector::from_column_slice(q0),
    };
    let levels = if n < 7 {
        vec![position(vec![0, 2]), joints(vec![0]), posture]
    } else {
        let orientation = LevelSpec {
            name: "tcp orientation".into(),
            task: TaskSpec::Orientation { frame: tcp },
            stiffness: diag(3, 60.0),
            damping: diag(3, 4.0),
            goal: DVector::from_vec(vec![roll + 0.2, pitch - 0.1, yaw + 0.3]),
        };
        let mut l = vec![position(vec![0, 1, 2]), orientation];
        if n > 7 {
            l.push(joints((0..n).step_by(4).collect()));
        }
        l.push(posture);
        l
    };
    ControllerSpec::new(levels)
}

/// `<target dir>/hcc-bench`: the bench binary runs from `<target dir>/<profile>/deps`.
fn out_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("current exe");
    exe.ancestors()
        .nth(3)
        .map(|t| t.join("hcc-bench"))
        .unwrap_or_else(|| PathBuf::from("hcc-bench"))
}

fn plot(path: &std::path::Path, rows: &[(usize, usize, support::Stats)]) -> Result<(), String> {
    plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
        .map_err(|_| "the bundled font could not be loaded".to_string())?;
    let e = |e: &dyn std::fmt::Debug| format!("{e:?}");
    let root = BitMapBackend::new(path, (900, 650)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let (n_last, _, s_last) = rows[rows.len() - 1];
    let lo = rows
        .iter()
        .map(|r| r.2.median)
        .fold(f64::INFINITY, f64::min)
        / 2.0;
    let hi = rows.iter().map(|r| r.2.p99).fold(0.0, f64::max) * 2.0;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "hcc-control: Controller::step time vs number of joints",
            (FONT, 24).into_font(),
        )
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((3.0f64..40.0).log_scale(), (lo..hi).log_scale())
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc("joints n")
        .y_desc("step time [µs]")
        .label_style((FONT, 15).into_font())
        .axis_desc_style((FONT, 17).into_font())
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| {
            if *v >= 10.0 {
                format!("{v:.0}")
            } else {
                format!("{v:.1}")
            }
        })
        .draw()
        .map_err(|x| e(&x))?;
    let blue = RGBColor(0, 90, 181);
    let red = RGBColor(220, 50, 32);
    let grey = RGBColor(110, 110, 110);
    for (label, color, get) in [
        (
            "median",
            blue,
            (|s: &support::Stats| s.median) as fn(&support::Stats) -> f64,
        ),
        ("p99", red, |s: &support::Stats| s.p99),
    ] {
        let pts: Vec<(f64, f64)> = rows.iter().map(|r| (r.0 as f64, get(&r.2))).collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
            .map_err(|x| e(&x))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(|x| e(&x))?;
    }
    for (label, power, style) in [
        ("n³ (through the median at n = 32)", 3, grey.stroke_width(2)),
        (
            "n² (through the median at n = 32)",
            2,
            grey.mix(0.5).stroke_width(1),
        ),
    ] {
        let f = |n: f64| s_last.median * (n / n_last as f64).powi(power);
        let pts: Vec<(f64, f64)> = (0..=40)
            .map(|k| 3.0 * (40.0f64 / 3.0).powf(k as f64 / 40.0))
            .filter(|&n| f(n) >= lo && f(n) <= hi)
            .map(|n| (n, f(n)))
            .collect();
        chart
            .draw_series(LineSeries::new(pts, style))
            .map_err(|x| e(&x))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font((FONT, 15).into_font())
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

fn main() {
    println!("hcc-control step time vs size (release, one Instant pair per call)");
    println!(
        "{:>3} {:>7} {:>8} {:>10} {:>10} {:>10} {:>10}",
        "n", "levels", "samples", "median µs", "p99 µs", "p99.9 µs", "max µs"
    );
    // Sizes given on the command line (`-- 32`) restrict the run.
    let only: Vec<usize> = std::env::args().filter_map(|a| a.parse().ok()).collect();
    let mut rows = Vec::new();
    let mut csv = String::from("n,levels,samples,median_us,p99_us,p999_us,max_us\n");
    for n in SIZES
        .into_iter()
        .filter(|n| only.is_empty() || only.contains(n))
    {
        let model = Model::from_urdf_str(&chain_urdf(n), None, "tcp", None).expect("chain URDF");
        let q0 = start_configuration(n);
        let spec = chain_spec(&model, &q0);
        let r = spec.levels.len();
        // About 3 s per size, between 10 000 and 50 000 samples.
        let probe = support::time_steps(&model, spec.clone(), &q0, 200, 1_000);
        let samples = ((3e6 / probe.median) as usize).clamp(10_000, 50_000);
        let s = support::time_steps(&model, spec, &q0, 2_000, samples);
        println!(
            "{n:>3} {r:>7} {:>8} {:>10.2} {:>10.2} {:>10.2} {:>10.2}",
            s.samples, s.median, s.p99, s.p999, s.max
        );
        writeln!(
            csv,
            "{n},{r},{},{:.3},{:.3},{:.3},{:.3}",
            s.samples, s.median, s.p99, s.p999, s.max
        )
        .unwrap();
        rows.push((n, r, s));
    }
    // Growth between successive sizes: the local exponent of t ∝ n^p.
    let slopes: Vec<String> = rows
        .windows(2)
        .map(|w| {
            let p = (w[1].2.median / w[0].2.median).ln() / (w[1].0 as f64 / w[0].0 as f64).ln();
            format!("{}→{}: n^{p:.2}", w[0].0, w[1].0)
        })
        .collect();
    println!("median growth {}", slopes.join(", "));
    if rows.len() < 2 {
        return;
    }
    let dir = out_dir();
    std::fs::create_dir_all(&dir).expect("output directory");
    let png = dir.join("controller_scaling.png");
    let csv_path = dir.join("controller_scaling.csv");
    std::fs::write(&csv_path, csv).expect("CSV");
    match plot(&png, &rows) {
        Ok(()) => println!("plot: {}\ntable: {}", png.display(), csv_path.display()),
        Err(e) => eprintln!("plot failed: {e}"),
    }
}
