//! The cycle's part of the load in the hand: a client's load message
//! checked, ramped in (module `load_ramp`) and answered (docs/load.md).

use hcc_msgs::{NO_KNOT, SetpointRejection};

use super::ControlCycle;

impl ControlCycle {
    /// Takes a client's load message ([`hcc_msgs::LoadSetpoint`],
    /// docs/load.md): checked (the message, then the physics and the payload
    /// limit), ramped in ([`ControlCycle::set_load`]) and answered in the
    /// client's slot like a setpoint. Returns the answer code.
    /// Allocation-free.
    pub fn take_load(&mut self, message: &hcc_msgs::LoadSetpoint) -> u32 {
        let code = match self.load_of(message) {
            Ok(load) => match self.set_load(&load, message.ramp()) {
                Ok(()) => hcc_msgs::ANSWER_ACCEPTED,
                Err(e) => load_rejection(&e).code(),
            },
            Err(r) => r.code(),
        };
        let (client, seq) = (message.client_id, message.header.seq);
        self.setpoints
            .record_answer(client, seq, 0, (code, NO_KNOT));
        self.setpoints.fill(&mut self.telemetry);
        code
    }

    fn load_of(
        &self,
        m: &hcc_msgs::LoadSetpoint,
    ) -> Result<hcc_model::Load, hcc_msgs::LoadRefusal> {
        m.validate()?;
        let i = &m.inertia;
        Ok(hcc_model::Load {
            mass: m.mass,
            com: nalgebra::Vector3::from(m.com),
            inertia: nalgebra::Matrix3::new(i[0], i[1], i[2], i[1], i[3], i[4], i[2], i[4], i[5]),
        })
    }

    /// The tip carries `load` from now on: the controller's model takes it
    /// over `ramp_s` s (module `load_ramp`), the contact detection quiet
    /// meanwhile. Refused when it is not a physical load or heavier than the
    /// model's payload limit. Allocation-free.
    pub fn set_load(
        &mut self,
        load: &hcc_model::Load,
        ramp_s: f64,
    ) -> Result<(), hcc_model::LoadError> {
        load.check(self.controller.model().payload_limit)?;
        let from = self.controller.model().load;
        self.load_ramp.start(from, *load, ramp_s);
        Ok(())
    }
}

/// The answer to a load the model refused.
fn load_rejection(e: &hcc_model::LoadError) -> hcc_msgs::LoadRefusal {
    use hcc_model::LoadError as E;
    use hcc_msgs::LoadRejection as R;
    match e {
        E::NonFinite => SetpointRejection::NonFinite.into(),
        E::NegativeMass(_) => R::NegativeMass.into(),
        E::AbovePayload { .. } => R::AbovePayload.into(),
        E::NotSymmetric | E::Inertia(_) => R::NotPhysical.into(),
    }
}
