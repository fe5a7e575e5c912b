//! What the recorder reads a cycle from: the controller's telemetry sample
//! (the law's output as the control cycle published it) and the law itself
//! (its terms at the recorded state). `hcc simulate` and the derivation of a
//! recording (`hcc run`, `hcc plot`) read the same two, so their rows agree.

use hcc_control::Controller;
use hcc_msgs::Telemetry;
use nalgebra::DMatrix;

use crate::{CycleOutput, LawTerms};

/// The law's output of one cycle as its telemetry carries it (τ after the
/// torque filter and the saturation, as commanded).
impl CycleOutput for Telemetry {
    fn tau(&self) -> &[f64] {
        Telemetry::tau(self)
    }
    fn level_torque(&self, i: usize) -> &[f64] {
        Telemetry::tau_level(self, i)
    }
    fn tau_mu(&self) -> &[f64] {
        &self.tau_mu[..self.n()]
    }
    fn task_error(&self, i: usize) -> &[f64] {
        Telemetry::task_error(self, i)
    }
    fn level_energy(&self, i: usize) -> f64 {
        self.storage[i]
    }
    fn p_mu(&self) -> f64 {
        self.p_mu
    }
    fn h(&self) -> Option<f64> {
        Some(self.h)
    }
    fn potential_in_h(&self, i: usize) -> Option<f64> {
        Some(self.potential[i])
    }
    fn tank(&self, i: usize) -> Option<(f64, f64)> {
        Some((self.tank[i], self.tank_valve[i]))
    }
    fn desired(&self, i: usize) -> Option<&[f64]> {
        let m = Telemetry::task_error(self, i).len();
        Some(&self.goal[i][..m])
    }
    fn external_torque(&self) -> Option<&[f64]> {
        Some(Telemetry::tau_ext(self))
    }
    fn contact(&self) -> Option<bool> {
        Some(Telemetry::contact(self))
    }
}

/// A cycle's output with the external wrench F̂ the control cycle estimated
/// (`hcc_cycle::ControlCycle::external_wrench`), which the telemetry does
/// not carry: everything else is `output`'s.
pub struct WithWrench<'a> {
    pub output: &'a dyn CycleOutput,
    pub wrench: &'a [f64],
}

impl CycleOutput for WithWrench<'_> {
    fn tau(&self) -> &[f64] {
        self.output.tau()
    }
    fn level_torque(&self, i: usize) -> &[f64] {
        self.output.level_torque(i)
    }
    fn tau_mu(&self) -> &[f64] {
        self.output.tau_mu()
    }
    fn task_error(&self, i: usize) -> &[f64] {
        self.output.task_error(i)
    }
    fn level_energy(&self, i: usize) -> f64 {
        self.output.level_energy(i)
    }
    fn p_mu(&self) -> f64 {
        self.output.p_mu()
    }
    fn h(&self) -> Option<f64> {
        self.output.h()
    }
    fn potential_in_h(&self, i: usize) -> Option<f64> {
        self.output.potential_in_h(i)
    }
    fn tank(&self, i: usize) -> Option<(f64, f64)> {
        self.output.tank(i)
    }
    fn desired(&self, i: usize) -> Option<&[f64]> {
        self.output.desired(i)
    }
    fn external_torque(&self) -> Option<&[f64]> {
        self.output.external_torque()
    }
    fn contact(&self) -> Option<bool> {
        self.output.contact()
    }
    fn external_wrench(&self) -> Option<&[f64]> {
        Some(self.wrench)
    }
}

/// The terms of the law after its step at the recorded state.
impl LawTerms for Controller {
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        Controller::task_jacobian(self, i)
    }
    fn level_potential(&self, i: usize) -> f64 {
        self.output().potential[i]
    }
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
        let d = self.diagnostics();
        Some((d.dims, d.jbar))
    }
}
