//! The row of one controller cycle: what the law computed, and the derived
//! columns (disturbing accelerations, the split of S_i, the plant's energy).

use crate::{RecordError, column_names};
use hcc_config::Scenario;
use hcc_model::{Data, Model};
use hcc_report::{CsvWriter, RunWriter, Trajectory};
use nalgebra::{DMatrix, DVector};

/// What the controller computed in one cycle, as the recorder reads it (from
/// the law in process, from the controller's telemetry over IPC). Levels are
/// 0-based.
pub trait CycleOutput {
    /// Torque applied, τ of eq. (19) (gravity included when the scenario asks for it).
    fn tau(&self) -> &[f64];
    /// Torque contribution τ_i of level `i`, eqs. (20)/(21).
    fn level_torque(&self, i: usize) -> &[f64];
    /// Coriolis cancellation τ_μ, eq. (22) (zero when disabled).
    fn tau_mu(&self) -> &[f64];
    /// Task error x̃_i = x_i − x_{i,d} of level `i`.
    fn task_error(&self, i: usize) -> &[f64];
    /// Level energy S_i, eqs. (26)/(28).
    fn level_energy(&self, i: usize) -> f64;
    /// Power of τ_μ, P_μ = τ_μᵀ q̇.
    fn p_mu(&self) -> f64;
    /// H, the storage of the arm and the controller (`hcc_msgs::Telemetry::h`;
    /// `None`: not known, the `H` column is NaN).
    fn h(&self) -> Option<f64> {
        None
    }
    /// Level `i`'s potential as H counts it (`None`: not known, the `V_<i>`
    /// column is NaN).
    fn potential_in_h(&self, _i: usize) -> Option<f64> {
        None
    }
    /// The energy in level `i`'s energy tank and its valve (`None`: not
    /// known, the `tank_<i>` and `valve_<i>` columns are NaN).
    fn tank(&self, _i: usize) -> Option<(f64, f64)> {
        None
    }
    /// Level `i`'s desired value x_{i,d} (`None`: not known, the
    /// `xd<i>_<k>` columns are NaN).
    fn desired(&self, _i: usize) -> Option<&[f64]> {
        None
    }
    /// The estimate r of the external joint torque (`None`: not known, the
    /// `tau_ext_<k>` columns are NaN).
    fn external_torque(&self) -> Option<&[f64]> {
        None
    }
    /// Whether a contact is flagged (`None`: not known, the `contact` column
    /// is NaN).
    fn contact(&self) -> Option<bool> {
        None
    }
    /// The estimate F̂ of the external wrench at the first position or pose
    /// level's frame, its task rows (`None`: not known, the `f_ext_<k>`
    /// columns are NaN; the telemetry does not carry it, the control cycle
    /// does — [`crate::WithWrench`]).
    fn external_wrench(&self) -> Option<&[f64]> {
        None
    }
}

/// Terms of the control law at the recorded state that the derived columns
/// need (in `hcc run`, those of a shadow copy of the controller fed with the
/// recorded states).
pub trait LawTerms {
    /// The analytic task Jacobian J_i of level `i` (m_i × n): selection rows of
    /// the frame Jacobian for a position, its angular rows for an orientation,
    /// selection or weights for a joint task.
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64>;
    /// Potential V_i(x̃_i) of level `i` (eq. 28; the rest of S_i is kinetic).
    fn level_potential(&self, i: usize) -> f64;
    /// The extended Jacobian J̄ of eq. (4), stacked level by level (row blocks
    /// of the sizes `dims` of v_i); `None` if the law has none. Needed only by
    /// a recorder with the `accv` columns.
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)>;
}

/// The mechanical energy of the plant, for the `E_kin` and `E_pot` columns.
pub trait EnergyModel {
    /// Kinetic and potential energy (E_kin, E_pot) at the state (q, q̇) at time `t`.
    fn energy_at(
        &mut self,
        t: f64,
        q: &DVector<f64>,
        qd: &DVector<f64>,
    ) -> Result<(f64, f64), RecordError>;
}

/// Where the rows go, one at a time.
pub trait RowSink {
    /// Takes one row (in the order of [`Recorder::columns`]).
    fn push_row(&mut self, row: &[f64]) -> Result<(), RecordError>;
}

impl RowSink for Trajectory {
    fn push_row(&mut self, row: &[f64]) -> Result<(), RecordError> {
        Ok(Trajectory::push_row(self, row)?)
    }
}

/// The results of a run written as the rows come (CSV, metrics, plots).
impl RowSink for RunWriter {
    fn push_row(&mut self, row: &[f64]) -> Result<(), RecordError> {
        Ok(RunWriter::push_row(self, row)?)
    }
}

/// A CSV table written as the rows come.
impl RowSink for CsvWriter {
    fn push_row(&mut self, row: &[f64]) -> Result<(), RecordError> {
        Ok(CsvWriter::push_row(self, row)?)
    }
}

/// One controller cycle: the state it sampled at time `t` and what it computed.
#[derive(Clone, Copy)]
pub struct Cycle<'a> {
    /// Time of the sampled state, s.
    pub t: f64,
    pub q: &'a [f64],
    pub qd: &'a [f64],
    pub output: &'a dyn CycleOutput,
    /// The law's terms at this state; `None` when they are unknown (the
    /// columns that need them, `acc`, `accv`, `S<i>_kin` and `S<i>_pot`, are NaN).
    pub law: Option<&'a dyn LawTerms>,
}

/// Builds the rows of a scenario's recording (see the crate documentation for
/// the columns). Allocates at construction only, apart from the law's J̄.
pub struct Recorder {
    columns: Vec<String>,
    model: Model,
    n: usize,
    /// m_i, the task dimensions.
    dims: Vec<usize>,
    /// The rows of the `f_ext_<k>` columns.
    wrench_rows: usize,
    with_v: bool,
    data: Data,
    /// Cholesky factor of M(q).
    m_chol: DMatrix<f64>,
    /// M⁻¹ τ_j for every level j, then for τ_μ.
    minv_tau: Vec<DVector<f64>>,
    /// J_i M⁻¹ τ_j per level i.
    acc: Vec<DVector<f64>>,
    q: DVector<f64>,
    qd: DVector<f64>,
    row: Vec<f64>,
    energy: Box<dyn EnergyModel>,
}

impl Recorder {
    /// A recorder of `scenario`; `with_v`: the law provides J̄, so the `accv`
    /// columns are recorded.
    pub fn new(
        scenario: &Scenario,
        with_v: bool,
        energy: Box<dyn EnergyModel>,
    ) -> Result<Recorder, RecordError> {
        let model = scenario.model.clone();
        let n = model.nq();
        let dims: Vec<usize> = scenario.task_dims();
        if dims.is_empty() {
            return Err(RecordError::Invalid(
                "the scenario has no level to record".into(),
            ));
        }
        let columns = column_names(scenario, with_v);
        Ok(Recorder {
            row: Vec::with_capacity(columns.len()),
            columns,
            data: Data::new(&model),
            m_chol: DMatrix::zeros(n, n),
            minv_tau: (0..=dims.len()).map(|_| DVector::zeros(n)).collect(),
            acc: dims.iter().map(|&m| DVector::zeros(m)).collect(),
            q: DVector::zeros(n),
            qd: DVector::zeros(n),
            model,
            n,
            dims,
            wrench_rows: crate::layout::wrench_rows(scenario),
            with_v,
            energy,
        })
    }

    /// Column names of the rows, in order.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// Whether the `accv` columns are recorded.
    pub fn with_extended_jacobian(&self) -> bool {
        self.with_v
    }

    /// An empty in-memory table with these columns, room for `rows` rows.
    pub fn trajectory(&self, rows: usize) -> Result<Trajectory, RecordError> {
        Ok(Trajectory::with_capacity(self.columns.clone(), rows)?)
    }

    /// The row built by the last [`Recorder::record`] (empty before the first).
    pub fn last_row(&self) -> &[f64] {
        &self.row
    }

    /// Builds the row of `cycle` and pushes it into `sink`.
    pub fn record<S: RowSink + ?Sized>(
        &mut self,
        cycle: &Cycle<'_>,
        sink: &mut S,
    ) -> Result<(), RecordError> {
        let t = cycle.t;
        self.check(cycle)?;
        self.q.as_mut_slice().copy_from_slice(cycle.q);
        self.qd.as_mut_slice().copy_from_slice(cycle.qd);
        // M(q) at the sampled state, for M⁻¹ τ_j.
        hcc_model::crba(&self.model, &mut self.data, &self.q);
        self.m_chol.copy_from(&self.data.m);
        hcc_model::linalg::cholesky_in_place(&mut self.m_chol)
            .map_err(|e| RecordError::Invalid(format!("M(q) at t = {t} s: {e}")))?;

        self.row.clear();
        self.push_law_columns(cycle);
        self.solve_minv_tau(cycle.output, t)?;
        match cycle.law {
            Some(law) => {
                self.push_task_accelerations(law);
                if self.with_v {
                    self.push_null_space_accelerations(law, t)?;
                }
            }
            None => {
                let r = self.dims.len();
                let blocks = if self.with_v { 2 } else { 1 };
                self.row
                    .extend(std::iter::repeat_n(f64::NAN, blocks * r * r));
            }
        }
        for i in 0..self.dims.len() {
            let pot = cycle.law.map_or(f64::NAN, |law| law.level_potential(i));
            self.row.push(cycle.output.level_energy(i) - pot);
            self.row.push(pot);
        }
        let (kinetic, potential) = self.energy.energy_at(t, &self.q, &self.qd)?;
        self.row.push(kinetic);
        self.row.push(potential);
        let out = cycle.output;
        self.row.push(out.h().unwrap_or(f64::NAN));
        for i in 0..self.dims.len() {
            self.row.push(out.potential_in_h(i).unwrap_or(f64::NAN));
        }
        let r = self.dims.len();
        let tanks = (0..r).map(|i| out.tank(i).map_or(f64::NAN, |t| t.0));
        self.row.extend(tanks);
        let valves = (0..r).map(|i| out.tank(i).map_or(f64::NAN, |t| t.1));
        self.row.extend(valves);
        self.push_contact_columns(cycle.output);
        for (i, &m) in self.dims.iter().enumerate() {
            match out.desired(i) {
                Some(x) if x.len() == m => self.row.extend_from_slice(x),
                _ => self.row.extend(std::iter::repeat_n(f64::NAN, m)),
            }
        }
        sink.push_row(&self.row)
    }

    /// Every vector of the cycle has the size of the scenario (a clear error
    /// instead of a panic in the arithmetic below).
    fn check(&self, cycle: &Cycle<'_>) -> Result<(), RecordError> {
        let (n, t, out) = (self.n, cycle.t, cycle.output);
        let wrong = |what: String, got: usize, expected: usize| {
            RecordError::Invalid(format!(
                "t = {t} s: {what} has length {got}, expected {expected}"
            ))
        };
        for (what, got) in [
            ("q", cycle.q.len()),
            ("qd", cycle.qd.len()),
            ("tau", out.tau().len()),
            ("tau_mu", out.tau_mu().len()),
        ] {
            if got != n {
                return Err(wrong(what.into(), got, n));
            }
        }
        for (i, &m) in self.dims.iter().enumerate() {
            let got = out.level_torque(i).len();
            if got != n {
                return Err(wrong(format!("the torque of level {}", i + 1), got, n));
            }
            let got = out.task_error(i).len();
            if got != m {
                return Err(wrong(format!("the task error of level {}", i + 1), got, m));
            }
            if let Some(law) = cycle.law {
                let j = law.task_jacobian(i);
                if j.shape() != (m, n) {
                    return Err(RecordError::Invalid(format!(
                        "t = {t} s: J_{} is {}×{}, expected {m}×{n}",
                        i + 1,
                        j.nrows(),
                        j.ncols()
                    )));
                }
            }
        }
        Ok(())
    }

    /// t, q, q̇, τ, x̃_i, S_i, P_μ, τ_i, τ_μ.
    fn push_law_columns(&mut self, cycle: &Cycle<'_>) {
        let (row, out, r) = (&mut self.row, cycle.output, self.dims.len());
        row.push(cycle.t);
        row.extend_from_slice(cycle.q);
        row.extend_from_slice(cycle.qd);
        row.extend_from_slice(out.tau());
        for i in 0..r {
            row.extend_from_slice(out.task_error(i));
        }
        for i in 0..r {
            row.push(out.level_energy(i));
        }
        row.push(out.p_mu());
        for i in 0..r {
            row.extend_from_slice(out.level_torque(i));
        }
        row.extend_from_slice(out.tau_mu());
    }

    /// `tau_ext_<k>`, `contact` and `f_ext_<k>` (NaN where the output does
    /// not know them).
    fn push_contact_columns(&mut self, out: &dyn CycleOutput) {
        match out.external_torque() {
            Some(r) if r.len() == self.n => self.row.extend_from_slice(r),
            _ => self.row.extend(std::iter::repeat_n(f64::NAN, self.n)),
        }
        self.row
            .push(out.contact().map_or(f64::NAN, |c| f64::from(u8::from(c))));
        match out.external_wrench() {
            Some(f) if f.len() == self.wrench_rows => self.row.extend_from_slice(f),
            _ => self
                .row
                .extend(std::iter::repeat_n(f64::NAN, self.wrench_rows)),
        }
    }

    /// M⁻¹ τ_j for every level j, then M⁻¹ τ_μ (by Cholesky solves).
    fn solve_minv_tau(&mut self, out: &dyn CycleOutput, t: f64) -> Result<(), RecordError> {
        let r = self.dims.len();
        for (j, x) in self.minv_tau.iter_mut().enumerate() {
            x.as_mut_slice().copy_from_slice(if j < r {
                out.level_torque(j)
            } else {
                out.tau_mu()
            });
            hcc_model::linalg::cholesky_solve_in_place(&self.m_chol, x)
                .map_err(|e| RecordError::Invalid(format!("M(q) solve at t = {t} s: {e}")))?;
        }
        Ok(())
    }

    /// ‖J_i M⁻¹ τ_j‖ for every j ≠ i, then ‖J_i M⁻¹ τ_μ‖ (Fig. 5).
    fn push_task_accelerations(&mut self, law: &dyn LawTerms) {
        for (i, acc_i) in self.acc.iter_mut().enumerate() {
            for (j, x) in self.minv_tau.iter().enumerate() {
                if j != i {
                    acc_i.gemv(1.0, law.task_jacobian(i), x, 0.0);
                    self.row.push(acc_i.norm());
                }
            }
        }
    }

    /// ‖J̄_i M⁻¹ τ_j‖ = ‖v̇_i‖ caused by τ_j, in the local null-space
    /// coordinates (eqs. 3, 4, 15).
    fn push_null_space_accelerations(
        &mut self,
        law: &dyn LawTerms,
        t: f64,
    ) -> Result<(), RecordError> {
        let (dims, jbar) = law
            .extended_jacobian()
            .ok_or_else(|| RecordError::Invalid(format!("t = {t} s: the controller gave no J̄")))?;
        let r = self.dims.len();
        if dims.len() != r || jbar.ncols() != self.n || dims.iter().sum::<usize>() != jbar.nrows() {
            return Err(RecordError::Invalid(format!(
                "t = {t} s: J̄ of the controller has an unexpected shape"
            )));
        }
        let mut offset = 0;
        for (i, &d) in dims.iter().enumerate() {
            let block = jbar.rows(offset, d);
            for (j, x) in self.minv_tau.iter().enumerate() {
                if j != i {
                    self.row.push((block * x).norm());
                }
            }
            offset += d;
        }
        Ok(())
    }
}
