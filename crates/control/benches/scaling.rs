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
use hcc_model::Model;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;
use support::chain::{chain_spec, chain_urdf, start_configuration};

const SIZES: [usize; 5] = [4, 7, 12, 20, 32];
const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../report/assets/DejaVuSans.ttf");

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
        let probe = support::time_steps(&model, spec.clone(), &q0, 200, 1_000, None);
        let samples = ((3e6 / probe.median) as usize).clamp(10_000, 50_000);
        let s = support::time_steps(&model, spec, &q0, 2_000, samples, None);
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
