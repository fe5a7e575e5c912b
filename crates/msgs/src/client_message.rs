//! A client's message of any kind: a setpoint, a path or a load message. A
//! client numbers the three together (one sequence across the three
//! services), so whoever reads more than one of them (a tap, a replay)
//! orders them by that number.

use crate::{LoadSetpoint, PathKnots, Setpoint};

/// A client's message, copied out of its queue.
#[derive(Clone, Debug)]
pub enum ClientMessage {
    /// A setpoint (`setpoint` service).
    Setpoint(Box<Setpoint>),
    /// A path message (`path` service).
    Path(Box<PathKnots>),
    /// A load message (`load` service).
    Load(Box<LoadSetpoint>),
}

impl ClientMessage {
    /// The client's sequence number, common to its three kinds of message.
    pub fn seq(&self) -> u64 {
        match self {
            Self::Setpoint(s) => s.header.seq,
            Self::Path(p) => p.header.seq,
            Self::Load(l) => l.header.seq,
        }
    }
}
