//! Building blocks of a robot driver for the hcc controller (Dietrich, Ott &
//! Albu-Schäffer, IROS 2013): the hardware interface a real robot implements
//! ([`hardware`]). The driver side of the message contract (which command may
//! be applied, hold/fallback/stop) is [`hcc_msgs::driver`], shared with the
//! simulated robot; the real-time runtime (absolute sleeps, the event wait,
//! the stop signal) is `hcc-rt`. The binary `hcc-driver-example` runs them
//! over iceoryx2 with a stub robot.

pub mod hardware;
