//! The load topic (`/<ns>/load`, docs/load.md): a ROS 2 node tells the
//! controller the load the robot's hand holds from now on.
//!
//! The type is `geometry_msgs/msg/InertiaStamped` (`common_interfaces`, no
//! extra package): mass `m` (kg), centre of mass `com` (m) and the
//! rotational inertia `ixx ixy ixz iyy iyz izz` (kg·m²) about the centre of
//! mass — the fields of `hcc_msgs::LoadSetpoint` and of a URDF `<inertial>`,
//! one for one. It is ROS 2's standard message for a body's mass
//! properties, and unlike Franka's `franka_msgs/srv/SetLoad` it needs no
//! vendor package on the sender's side.
//! The header's `frame_id` must be empty or the robot's tip link: the
//! centre of mass and the inertia's axes are the tip frame's. The ramp is
//! the bridge's `--load-ramp` (0: the controller's default).
//!
//! The message becomes one `hcc_msgs::LoadSetpoint`, sent through the
//! bridge's client; the controller checks it (payload limit, physical
//! inertia) and its answer is the publisher's `remote_answers` entry, with
//! [`LOAD_LEVEL`] as its level.

use crate::cdr::{CdrError, CdrReader};
use crate::names::RosType;

/// `geometry_msgs/msg/InertiaStamped`.
pub const INERTIA_STAMPED: RosType = RosType {
    name: "geometry_msgs/msg/InertiaStamped",
    hash: "RIHS01_766be45976252babf7f9d8ac4ae7c912a7ceccf71035622529f27518b695aa09",
};

/// The level of a load's remote answer (`hcc_msgs/msg/RemoteAnswer`): no
/// level's index.
pub const LOAD_LEVEL: u32 = u32::MAX;

/// Why a load message was refused by the bridge.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LoadMsgError {
    /// The message could not be read.
    #[error(transparent)]
    Cdr(#[from] CdrError),
    /// The frame is not the tip link.
    #[error("frame_id {got:?} is not the robot's tip link {tip:?} (or empty)")]
    Frame { got: String, tip: String },
}

/// Reads an `InertiaStamped` as the load it tells, for a robot whose tip
/// link is `tip`; the ramp is `ramp_s` (0: the controller's default). The
/// controller checks the values.
pub fn read_load(
    payload: &[u8],
    tip: &str,
    ramp_s: f64,
) -> Result<hcc_msgs::LoadSetpoint, LoadMsgError> {
    let mut r = CdrReader::new(payload)?;
    r.i32("header.stamp.sec")?;
    r.u32("header.stamp.nanosec")?;
    let frame = r.string("header.frame_id")?;
    if !(frame.is_empty() || frame == tip) {
        return Err(LoadMsgError::Frame {
            got: frame.to_owned(),
            tip: tip.to_owned(),
        });
    }
    let mut load = hcc_msgs::LoadSetpoint::zeroed();
    load.mass = r.f64("inertia.m")?;
    for c in &mut load.com {
        *c = r.f64("inertia.com")?;
    }
    // ixx ixy ixz iyy iyz izz: the message's order and LoadSetpoint's.
    for i in &mut load.inertia {
        *i = r.f64("inertia.i")?;
    }
    load.ramp_s = ramp_s;
    Ok(load)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::CdrWriter;

    fn message(frame: &str, values: &[f64]) -> Vec<u8> {
        let mut w = CdrWriter::new();
        w.start().i32(5).u32(6).string(frame);
        for &v in values {
            w.f64(v);
        }
        w.bytes().to_vec()
    }

    #[test]
    fn an_inertia_stamped_is_read_field_for_field() {
        let v = [1.5, 0.01, -0.02, 0.1, 0.004, 1e-4, 2e-4, 0.005, 3e-4, 0.006];
        let l = read_load(&message("tcp", &v), "tcp", 0.3).unwrap();
        assert_eq!(l.mass, 1.5);
        assert_eq!(l.com, [0.01, -0.02, 0.1]);
        assert_eq!(l.inertia, [0.004, 1e-4, 2e-4, 0.005, 3e-4, 0.006]);
        assert_eq!(l.ramp_s, 0.3);
        assert_eq!(l.client_id, 0, "the client fills in its identity");
        // An empty frame is the tip's.
        assert!(read_load(&message("", &v), "tcp", 0.0).is_ok());
    }

    #[test]
    fn another_frame_or_a_short_message_is_refused() {
        let v = [1.0; 10];
        assert_eq!(
            read_load(&message("world", &v), "tcp", 0.0).unwrap_err(),
            LoadMsgError::Frame {
                got: "world".into(),
                tip: "tcp".into()
            }
        );
        let short = message("tcp", &v[..9]);
        assert!(matches!(
            read_load(&short, "tcp", 0.0),
            Err(LoadMsgError::Cdr(_))
        ));
    }
}
