//! `/load`: a client's load message ([`LoadSetpoint`], docs/load.md) as the
//! controller received it, so that a run in which the hand's load was told
//! at run time replays bit for bit. Numbers as in every message of a
//! recording (shortest round-trip form; NaN as `null`).

use hcc_msgs::LoadSetpoint;
use serde::{Deserialize, Serialize};

use super::messages::{num, nums};

/// `/load`: one [`LoadSetpoint`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LoadMsg {
    pub seq: u64,
    pub stamp_ns: u64,
    pub schema_version: u32,
    pub n_joints: u32,
    pub client_id: u64,
    /// kg.
    #[serde(deserialize_with = "num")]
    pub mass: f64,
    /// Centre of mass in the tip frame, m.
    #[serde(deserialize_with = "nums")]
    pub com: Vec<f64>,
    /// About the centre of mass, tip axes, kg·m²: ixx ixy ixz iyy iyz izz.
    #[serde(deserialize_with = "nums")]
    pub inertia: Vec<f64>,
    /// As sent (0: the controller's default).
    #[serde(deserialize_with = "num")]
    pub ramp_s: f64,
}

impl From<&LoadSetpoint> for LoadMsg {
    fn from(l: &LoadSetpoint) -> Self {
        LoadMsg {
            seq: l.header.seq,
            stamp_ns: l.header.stamp_ns,
            schema_version: l.header.schema_version,
            n_joints: l.header.n_joints,
            client_id: l.client_id,
            mass: l.mass,
            com: l.com.to_vec(),
            inertia: l.inertia.to_vec(),
            ramp_s: l.ramp_s,
        }
    }
}

impl LoadMsg {
    /// The contract message.
    pub fn to_msg(&self) -> Result<LoadSetpoint, String> {
        let mut l = LoadSetpoint::zeroed();
        l.header.seq = self.seq;
        l.header.stamp_ns = self.stamp_ns;
        l.header.schema_version = self.schema_version;
        l.header.n_joints = self.n_joints;
        l.client_id = self.client_id;
        l.mass = self.mass;
        l.com = self
            .com
            .as_slice()
            .try_into()
            .map_err(|_| format!("load: com has {} entries, not 3", self.com.len()))?;
        l.inertia = self
            .inertia
            .as_slice()
            .try_into()
            .map_err(|_| format!("load: inertia has {} entries, not 6", self.inertia.len()))?;
        l.ramp_s = self.ramp_s;
        Ok(l)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_load_round_trips_bit_for_bit_and_a_short_one_is_an_error() {
        let mut l = LoadSetpoint::point(7, 12, 1.0 / 3.0, [0.0, 1e-17, 0.1]);
        l.header.stamp_ns = 123_456_789;
        l.inertia = [1e-3, 0.0, -2e-5, 1.5e-3, 0.0, 2e-3];
        l.ramp_s = 0.25;
        let json = serde_json::to_string(&LoadMsg::from(&l)).unwrap();
        let back: LoadMsg = serde_json::from_str(&json).unwrap();
        assert_eq!(back.to_msg().unwrap(), l, "{json}");
        // A NaN (a raw client's; the controller refuses it) reads back.
        let mut nan = l;
        nan.mass = f64::NAN;
        let json = serde_json::to_string(&LoadMsg::from(&nan)).unwrap();
        let back_nan: LoadMsg = serde_json::from_str(&json).unwrap();
        assert!(back_nan.to_msg().unwrap().mass.is_nan(), "{json}");
        let mut short = back;
        short.com.pop();
        assert!(short.to_msg().unwrap_err().contains("com has 2"));
    }
}
