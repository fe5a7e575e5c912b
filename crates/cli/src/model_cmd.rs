//! `hcc model`: the robot model's dynamics at given states, as JSON.
//!
//! Reads `{"states":[{"q":[...],"qd":[...],"tau":[...]}]}` (`qd` and `tau`
//! default to zero) and prints, per state, the keys of the reference file
//! `tests/data/panda_dynamics.json`: q, qd, tau, M, C, g, nle,
//! qdd_forward_dynamics, tip_position, tip_rotation, tip_jacobian, tip_jdot_qd
//! (matrices as row-major arrays of rows).

use anyhow::{Context, bail};
use hcc_model::{
    Data, Model, compute_all_terms, forward_dynamics, frame_classical_acceleration, frame_jacobian,
    frame_placement,
};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ModelArgs {
    /// URDF file of the robot.
    #[arg(long)]
    pub urdf: PathBuf,
    /// Tip link of the chain.
    #[arg(long)]
    pub tip: String,
    /// Gravity vector X,Y,Z in m/s².
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub gravity: Option<Vec<f64>>,
    /// JSON file {"states":[{"q":[...],"qd":[...],"tau":[...]}]}.
    #[arg(long)]
    pub states: PathBuf,
}

/// Other top-level keys (e.g. those of a reference file) are ignored.
#[derive(Deserialize)]
struct StatesFile {
    states: Vec<StateIn>,
}

#[derive(Deserialize)]
struct StateIn {
    q: Vec<f64>,
    #[serde(default)]
    qd: Option<Vec<f64>>,
    #[serde(default)]
    tau: Option<Vec<f64>>,
}

#[derive(Serialize)]
struct Output {
    urdf: String,
    root_link: String,
    tip_link: String,
    active_joints: Vec<String>,
    locked_joints: Vec<String>,
    gravity: [f64; 3],
    states: Vec<StateOut>,
}

#[derive(Serialize)]
#[allow(non_snake_case)]
struct StateOut {
    q: Vec<f64>,
    qd: Vec<f64>,
    tau: Vec<f64>,
    M: Vec<Vec<f64>>,
    C: Vec<Vec<f64>>,
    g: Vec<f64>,
    nle: Vec<f64>,
    qdd_forward_dynamics: Vec<f64>,
    tip_position: Vec<f64>,
    tip_rotation: Vec<Vec<f64>>,
    tip_jacobian: Vec<Vec<f64>>,
    tip_jdot_qd: Vec<f64>,
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// A state vector of length `n`, or zeros when absent.
fn vector(
    v: Option<Vec<f64>>,
    n: usize,
    file: &str,
    index: usize,
    key: &str,
) -> anyhow::Result<DVector<f64>> {
    let v = v.unwrap_or_else(|| vec![0.0; n]);
    if v.len() != n {
        bail!(
            "{file}: states[{index}].{key} has {} entries, the chain has {n} joints",
            v.len()
        );
    }
    if let Some(k) = v.iter().position(|x| !x.is_finite()) {
        bail!("{file}: states[{index}].{key}[{k}] is not finite");
    }
    Ok(DVector::from_vec(v))
}

pub fn run(args: ModelArgs) -> anyhow::Result<()> {
    let gravity = match &args.gravity {
        None => None,
        Some(g) if g.len() == 3 => Some(Vector3::new(g[0], g[1], g[2])),
        Some(g) => bail!("--gravity needs three values X,Y,Z, got {}", g.len()),
    };
    let model = Model::from_urdf_file(&args.urdf, None, &args.tip, gravity)?;
    let file = args.states.display().to_string();
    let text = std::fs::read_to_string(&args.states)
        .with_context(|| format!("{file}: cannot read states file"))?;
    let input: StatesFile = serde_json::from_str(&text).with_context(|| {
        format!("{file}: expected {{\"states\":[{{\"q\":[...],\"qd\":[...],\"tau\":[...]}}]}}")
    })?;

    let n = model.nq();
    let tip = model.tip_frame();
    let mut data = Data::new(&model);
    let mut jacobian = DMatrix::zeros(6, n);
    let mut states = Vec::with_capacity(input.states.len());
    for (index, s) in input.states.into_iter().enumerate() {
        let q = vector(Some(s.q), n, &file, index, "q")?;
        let qd = vector(s.qd, n, &file, index, "qd")?;
        let tau = vector(s.tau, n, &file, index, "tau")?;

        compute_all_terms(&model, &mut data, &q, &qd);
        let m = data.m.clone();
        let c = data.c.clone();
        let g = data.g.clone();
        let nle = data.nle.clone();
        let o_m = frame_placement(&model, &data, tip);
        frame_jacobian(&model, &data, tip, &mut jacobian);
        let jdot_qd = frame_classical_acceleration(&model, &data, tip);
        forward_dynamics(&model, &mut data, &q, &qd, &tau)
            .with_context(|| format!("{file}: states[{index}]: forward dynamics"))?;
        let rotation = o_m.rotation.to_rotation_matrix();
        let rotation = DMatrix::from_column_slice(3, 3, rotation.matrix().as_slice());

        states.push(StateOut {
            q: q.iter().copied().collect(),
            qd: qd.iter().copied().collect(),
            tau: tau.iter().copied().collect(),
            M: rows(&m),
            C: rows(&c),
            g: g.iter().copied().collect(),
            nle: nle.iter().copied().collect(),
            qdd_forward_dynamics: data.qdd.iter().copied().collect(),
            tip_position: o_m.translation.vector.iter().copied().collect(),
            tip_rotation: rows(&rotation),
            tip_jacobian: rows(&jacobian),
            tip_jdot_qd: jdot_qd.iter().copied().collect(),
        });
    }
    let output = Output {
        urdf: args.urdf.display().to_string(),
        root_link: model.root_link.clone(),
        tip_link: model.tip_link.clone(),
        active_joints: model.joints.iter().map(|j| j.name.clone()).collect(),
        locked_joints: model.locked_joints.clone(),
        gravity: [model.gravity.x, model.gravity.y, model.gravity.z],
        states,
    };
    println!("{}", serde_json::to_string_pretty(&output)?);
    Ok(())
}
