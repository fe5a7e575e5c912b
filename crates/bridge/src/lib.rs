//! # hcc-bridge — the system on Zenoh, readable and commandable by ROS 2 nodes
//!
//! `hcc bridge --namespace NS --config SCENARIO.toml [--domain D]
//! [--zenoh-config FILE] [--rate HZ] [--allow-setpoints]` is a process of
//! its own (tokio and Zenoh never enter the daemons): a pure iceoryx2
//! subscriber of a namespace's joint states, torque commands and telemetry
//! ([`ipc_side`], like `hcc record`) that publishes them on Zenoh in the
//! wire format of `rmw_zenoh` (ROS 2 Jazzy and later), so that ROS 2 nodes
//! with `RMW_IMPLEMENTATION=rmw_zenoh_cpp` see them as topics with no ROS
//! code in hcc:
//!
//! | topic                    | type                              | content |
//! |--------------------------|-----------------------------------|---------|
//! | `/<ns>/joint_states`     | `sensor_msgs/msg/JointState`      | names (URDF), position, velocity, measured effort |
//! | `/<ns>/torque_command`   | `sensor_msgs/msg/JointState`      | names, effort = the commanded τ |
//! | `/<ns>/telemetry`        | `hcc_msgs/msg/Telemetry`          | levels (errors, goals, gains, S_i), P_μ, counters, answers |
//! | `/<ns>/<level>/goal`     | PoseStamped, PointStamped, QuaternionStamped or Float64MultiArray ([`goal`]) | a remote goal (subscribed) |
//! | `/<ns>/<level>/path`     | JointTrajectory or MultiDOFJointTrajectory ([`trajectory`]) | a remote path (subscribed) |
//! | `/<ns>/load`             | `geometry_msgs/msg/InertiaStamped` ([`load`]) | the load in the hand (subscribed) |
//!
//! The real-time loops never wait for the bridge: its subscribers drain
//! the queues every millisecond, count what they lost, decimate to `--rate`
//! (default 100 Hz, at most 1000) and drop (and count) what the Zenoh side
//! cannot take. Remote goals become setpoints only with `--allow-setpoints`
//! (otherwise they are refused and answered), through `hcc-client` as one
//! client of the controller, at most `--setpoint-rate` per second; the
//! controller validates them (limits, workspace, rates) as any local
//! setpoint, and its answer appears in the telemetry topic
//! (`remote_answers`, keyed by the remote publisher's GID and sequence
//! number).
//!
//! Wire format (rmw_zenoh's design notes and `liveliness_utils.cpp`,
//! `attachment_helpers.cpp`): [`names`] (key expressions, liveliness
//! tokens, GIDs), [`attachment`], [`cdr`] (plain CDR, XCDR1), [`ros`] (the
//! messages and their RIHS01 type hashes).

pub mod attachment;
pub mod cdr;
pub mod counters;
pub mod goal;
pub mod ipc_side;
pub mod load;
pub mod names;
pub mod rate;
pub mod ros;
mod run;
pub mod trajectory;
pub mod zenoh_side;

pub use run::{Args, run};
