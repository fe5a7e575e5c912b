//! Building blocks of a robot driver for the hcc controller (Dietrich, Ott &
//! Albu-Schäffer, IROS 2013): the driver side of the hcc-msgs contract
//! ([`contract`]: which command may be applied, hold/fallback/stop) and the
//! hardware interface a real robot implements ([`hardware`]). The binary
//! `hcc-driver-example` runs them over iceoryx2 with a stub robot.

pub mod contract;
pub mod hardware;
