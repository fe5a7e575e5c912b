//! The levels' desired paths (a scenario level's `trajectory = "FILE.csv"`)
//! and which levels get the tracking form's feed-forward (`feed_forward`,
//! default true; docs/tracking.md).

use crate::TaskSpec;
use hcc_trajectory::{Block, Trajectory};

/// A level's path as the scenario names it.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelPath {
    /// The file as written in the scenario (relative to it).
    pub file: String,
    /// The file's text.
    pub text: String,
    /// The path it describes.
    pub trajectory: Trajectory,
}

/// What the control cycle does with the levels' paths.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tracking {
    /// Per level, its path (`None`: its goal).
    pub paths: Vec<Option<LevelPath>>,
    /// Per level, whether it gets the feed-forward while any level follows
    /// a path (a level with a fixed goal then tracks that constant goal);
    /// false: its goal is pulled along as by a transition.
    pub feed_forward: Vec<bool>,
}

impl Tracking {
    /// Whether any level follows a path.
    pub fn any(&self) -> bool {
        self.paths.iter().any(Option::is_some)
    }
}

/// The blocks of a level's coordinates in a path file, task by task: a
/// position's axes, a 3-D orientation's quaternion, a pose's x y z and
/// quaternion, a joint task's joints, a combination's rows, a planar
/// rotation's angle.
pub fn blocks(tasks: &[TaskSpec], n: usize) -> Vec<Block> {
    let mut out = Vec::new();
    for t in tasks {
        match t {
            TaskSpec::Orientation { .. } => out.push(Block::Rotation),
            TaskSpec::Pose { .. } => {
                out.push(Block::Vector(3));
                out.push(Block::Rotation);
            }
            other => out.push(Block::Vector(other.dim(n))),
        }
    }
    out
}
