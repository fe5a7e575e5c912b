//! The plant's mechanical energy for the recorder's `E_kin`, `E_pot` columns.

use hcc_config::Scenario;
use hcc_plant::{Plant, SimError};
use hcc_record::{EnergyModel, RecordError, Recorder};
use nalgebra::DVector;

/// A plant of the scenario, asked for its energy at a recorded state.
pub struct PlantEnergyModel(pub Plant);

impl EnergyModel for PlantEnergyModel {
    fn energy_at(
        &mut self,
        t: f64,
        q: &DVector<f64>,
        qd: &DVector<f64>,
    ) -> Result<(f64, f64), RecordError> {
        self.0
            .set_state(t, q, qd)
            .map_err(|e| RecordError::Invalid(e.to_string()))?;
        let energy = self.0.energy();
        Ok((energy.kinetic, energy.potential))
    }
}

/// The recorder of `scenario`'s rows, with the `accv` columns (the law's J̄),
/// the plant's energy taken from the scenario's plant.
pub fn recorder(scenario: &Scenario) -> Result<Recorder, SimError> {
    let energy = PlantEnergyModel(hcc_plant::plant_for(scenario)?);
    Recorder::new(scenario, true, Box::new(energy)).map_err(|e| SimError::Invalid(e.to_string()))
}
