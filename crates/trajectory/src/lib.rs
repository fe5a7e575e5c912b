//! Desired paths of a hierarchy's levels (docs/tracking.md): a level's
//! x_{i,d}(t), ẋ_{i,d}(t), ẍ_{i,d}(t) from a table of rows `t, c1, c2, …`.
//!
//! A level's coordinates are [`Block`]s: vectors (a position's x y z in m, a
//! joint level's values in rad, any other task's coordinates) and
//! orientations (a unit quaternion w x y z in the file; roll, pitch, yaw as
//! the level's goal; the world angular velocity and acceleration as its
//! rates). Each vector coordinate is interpolated C² (`spline.rs`: the
//! clamped cubic spline inside, quintic end segments that start and end at
//! rest); an orientation is interpolated on SO(3) (`rotation.rs`): its
//! rotation vector relative to the first row's orientation, r_k =
//! log(R_0ᵀ R_k), is interpolated as above, and ω, ω̇ follow from the right
//! Jacobian of SO(3) — not from component-wise quaternion derivatives. After
//! the last row the last value is held with zero velocity and acceleration.
//!
//! [`Trajectory::parse`] reads and checks a file (allocates);
//! [`Trajectory::sample`] allocates nothing (a 1 kHz loop calls it).
//! [`PathStream`] is the path that arrives while it runs (knots appended to
//! a preallocated ring, interpolated from local data so that nothing already
//! executing changes; `stream.rs`).
//!
//! ```
//! use hcc_trajectory::{Block, Trajectory};
//! let text = "t,x,y,z\n0,0.4,0.0,0.5\n1,0.4,0.1,0.5\n2,0.4,0.0,0.5\n";
//! let path = Trajectory::parse(text, &[Block::Vector(3)]).unwrap();
//! let mut s = path.sample_buffer();
//! path.sample(1.0, &mut s);
//! assert!((s.goal[1] - 0.1).abs() < 1e-12);
//! path.sample(5.0, &mut s); // held after the last row, at rest
//! assert_eq!(s.velocity, vec![0.0; 3]);
//! ```

mod csv;
mod rotation;
mod spline;
mod stream;

use nalgebra::{UnitQuaternion, Vector3};
use spline::Quintic;
pub use stream::{KnotError, PathStream, StreamState};

/// How far a quaternion's norm may be from 1 (it is then normalised).
pub const UNIT_TOLERANCE: f64 = 1e-3;

/// The unit quaternion of the columns w x y z (normalised), or `None` when
/// their norm is more than [`UNIT_TOLERANCE`] from 1 (or not finite). The
/// one reading of an orientation's columns: files, knots, goals.
pub(crate) fn unit_quaternion(w: &[f64]) -> Option<UnitQuaternion<f64>> {
    let q = nalgebra::Quaternion::new(w[0], w[1], w[2], w[3]);
    let norm = q.norm();
    ((norm - 1.0).abs() <= UNIT_TOLERANCE).then(|| UnitQuaternion::new_normalize(q))
}

/// How far (rad) an orientation may turn from the path's first orientation:
/// its rotation vector is interpolated relative to it, unique below π.
pub const MAX_TURN: f64 = 0.9 * std::f64::consts::PI;

/// A group of a level's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Block {
    /// `k` coordinates interpolated each on its own (m, rad, …).
    Vector(usize),
    /// An orientation: 4 columns (w x y z), 3 goal values (roll, pitch, yaw),
    /// 3 rates (world angular velocity, acceleration).
    Rotation,
}

impl Block {
    /// Its columns in the file.
    pub fn columns(&self) -> usize {
        match self {
            Block::Vector(k) => *k,
            Block::Rotation => 4,
        }
    }

    /// Its values in the level's goal, and in its velocity and acceleration.
    pub fn dim(&self) -> usize {
        match self {
            Block::Vector(k) => *k,
            Block::Rotation => 3,
        }
    }
}

/// Why a file was refused: the line (1-based; 0 for the file as a whole) and
/// the reason.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}{reason}", if *row > 0 { format!("row {row}: ") } else { String::new() })]
pub struct TrajectoryError {
    /// The line of the file.
    pub row: usize,
    /// What is wrong with it.
    pub reason: String,
}

impl TrajectoryError {
    pub(crate) fn at(row: usize, reason: String) -> TrajectoryError {
        TrajectoryError { row, reason }
    }
}

/// A level's desired value at one instant (preallocated by
/// [`Trajectory::sample_buffer`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PathSample {
    /// x_d in the level's goal format (an orientation as roll, pitch, yaw).
    pub goal: Vec<f64>,
    /// ẋ_d (an orientation's world angular velocity, rad/s).
    pub velocity: Vec<f64>,
    /// ẍ_d (an orientation's world angular acceleration, rad/s²).
    pub acceleration: Vec<f64>,
}

/// A level's path: its knots, each coordinate's segments, the orientations'
/// reference rotations.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    blocks: Vec<Block>,
    times: Vec<f64>,
    /// Per interpolated coordinate (a vector's values, an orientation's
    /// rotation-vector components) its segments (none for a single row) and
    /// the value held after the last row.
    segments: Vec<Vec<Quintic>>,
    held: Vec<f64>,
    /// Per orientation block, R_0 (the first row's orientation).
    references: Vec<UnitQuaternion<f64>>,
    /// The file's line of the first row (after the header).
    first_line: usize,
}

impl Trajectory {
    /// Reads a file's text for a level of `blocks`: the header, the rows, t
    /// from 0 strictly increasing, finite values, unit quaternions, no
    /// orientation more than [`MAX_TURN`] from the first.
    pub fn parse(text: &str, blocks: &[Block]) -> Result<Trajectory, TrajectoryError> {
        Trajectory::from_rows(&csv::rows(text, blocks)?, blocks)
    }

    /// The path through checked rows (line, t, columns).
    fn from_rows(
        rows: &[(usize, f64, Vec<f64>)],
        blocks: &[Block],
    ) -> Result<Trajectory, TrajectoryError> {
        let times: Vec<f64> = rows.iter().map(|r| r.1).collect();
        // Each interpolated coordinate's values at the knots.
        let mut coords: Vec<Vec<f64>> = Vec::new();
        let mut references = Vec::new();
        let mut c = 0;
        for b in blocks {
            match b {
                Block::Vector(k) => {
                    for a in 0..*k {
                        coords.push(rows.iter().map(|r| r.2[c + a]).collect());
                    }
                }
                Block::Rotation => {
                    // Unit quaternions already (the rows are checked).
                    let q = |v: &[f64]| {
                        unit_quaternion(&v[c..c + 4]).unwrap_or_else(UnitQuaternion::identity)
                    };
                    let r0 = q(&rows[0].2);
                    let mut r: Vec<Vec<f64>> =
                        (0..3).map(|_| Vec::with_capacity(rows.len())).collect();
                    for (line, _, v) in rows {
                        let rv = (r0.inverse() * q(v)).scaled_axis();
                        if rv.norm() > MAX_TURN {
                            return Err(TrajectoryError::at(
                                *line,
                                format!(
                                    "the orientation turns {:.3} rad from the first row's (at most \
                                     {MAX_TURN:.3}): split the path",
                                    rv.norm()
                                ),
                            ));
                        }
                        for a in 0..3 {
                            r[a].push(rv[a]);
                        }
                    }
                    coords.extend(r);
                    references.push(r0);
                }
            }
            c += b.columns();
        }
        let held = coords.iter().map(|y| y[y.len() - 1]).collect();
        let segments = coords
            .iter()
            .map(|y| {
                if y.len() < 2 {
                    Vec::new()
                } else {
                    spline::segments(&times, y)
                }
            })
            .collect();
        Ok(Trajectory {
            blocks: blocks.to_vec(),
            times,
            segments,
            held,
            references,
            first_line: rows[0].0,
        })
    }

    /// The level's blocks.
    pub fn blocks(&self) -> &[Block] {
        &self.blocks
    }

    /// The time of the last row (s): from then on the path holds.
    pub fn duration(&self) -> f64 {
        self.times[self.times.len() - 1]
    }

    /// The file's line of the first row (1-based; errors about where the
    /// path starts name it).
    pub fn first_line(&self) -> usize {
        self.first_line
    }

    /// The number of rows.
    pub fn rows(&self) -> usize {
        self.times.len()
    }

    /// A sample's buffers for this path.
    pub fn sample_buffer(&self) -> PathSample {
        let m: usize = self.blocks.iter().map(Block::dim).sum();
        PathSample {
            goal: vec![0.0; m],
            velocity: vec![0.0; m],
            acceleration: vec![0.0; m],
        }
    }

    /// The desired value at t s (t ≤ 0: the first row; after the last row:
    /// the last, at rest) into `out` (from [`Trajectory::sample_buffer`]).
    /// Allocation-free.
    pub fn sample(&self, t: f64, out: &mut PathSample) {
        let last = self.times.len() - 1;
        let hold = last == 0 || t >= self.times[last];
        let (k, h, s) = if hold {
            (0, 1.0, 0.0)
        } else {
            let t = t.max(0.0);
            let k = (self.times.partition_point(|&tk| tk <= t).max(1) - 1).min(last - 1);
            let h = self.times[k + 1] - self.times[k];
            (k, h, (t - self.times[k]) / h)
        };
        let coord = |i: usize| -> [f64; 3] {
            if hold {
                [self.held[i], 0.0, 0.0]
            } else {
                spline::evaluate(&self.segments[i][k], h, s)
            }
        };
        assemble(&self.blocks, &self.references, coord, out);
    }
}

/// The rows of a path file's `text` for a level of `blocks`, checked as
/// [`Trajectory::parse`] checks them (header, t from 0 increasing, finite,
/// unit quaternions, normalised): (t, columns) each — what a client sends
/// as a path's knots.
pub fn read_rows(text: &str, blocks: &[Block]) -> Result<Vec<(f64, Vec<f64>)>, TrajectoryError> {
    let rows = csv::rows(text, blocks)?;
    // The turn limit (a knot the controller would refuse) as a file's.
    Trajectory::from_rows(&rows, blocks)?;
    Ok(rows.into_iter().map(|(_, t, v)| (t, v)).collect())
}

/// A knot's `columns` (a path file's: a vector's values, an orientation's
/// quaternion w x y z) in the level's goal format (an orientation as roll,
/// pitch, yaw) into `goal`. `false` for a wrong number of columns or an
/// orientation that is not a unit quaternion (within 1e-3). Allocation-free.
pub fn goal_of(blocks: &[Block], columns: &[f64], goal: &mut [f64]) -> bool {
    let need: usize = blocks.iter().map(Block::columns).sum();
    let dim: usize = blocks.iter().map(Block::dim).sum();
    if columns.len() != need || goal.len() != dim {
        return false;
    }
    let (mut c, mut g) = (0, 0);
    for b in blocks {
        match b {
            Block::Vector(n) => goal[g..g + n].copy_from_slice(&columns[c..c + n]),
            Block::Rotation => {
                let Some(q) = unit_quaternion(&columns[c..c + 4]) else {
                    return false;
                };
                let (roll, pitch, yaw) = q.euler_angles();
                goal[g..g + 3].copy_from_slice(&[roll, pitch, yaw]);
            }
        }
        c += b.columns();
        g += b.dim();
    }
    true
}

/// A sample from each interpolated coordinate's position, velocity and
/// acceleration (`coord(i)`): vector blocks as they are, an orientation
/// block's rotation vector r relative to its reference R_0 as the goal's
/// roll, pitch, yaw of R_0 exp([r]×) and the world ω, ω̇ (`rotation.rs`).
pub(crate) fn assemble(
    blocks: &[Block],
    references: &[UnitQuaternion<f64>],
    coord: impl Fn(usize) -> [f64; 3],
    out: &mut PathSample,
) {
    let (mut i, mut g, mut rot) = (0, 0, 0);
    for b in blocks {
        match b {
            Block::Vector(n) => {
                for a in 0..*n {
                    let [p, v, acc] = coord(i + a);
                    out.goal[g + a] = p;
                    out.velocity[g + a] = v;
                    out.acceleration[g + a] = acc;
                }
                i += n;
                g += n;
            }
            Block::Rotation => {
                let (mut r, mut rd, mut rdd) =
                    (Vector3::zeros(), Vector3::zeros(), Vector3::zeros());
                for a in 0..3 {
                    [r[a], rd[a], rdd[a]] = coord(i + a);
                }
                let rotation = references[rot] * UnitQuaternion::from_scaled_axis(r);
                let (wb, wdb) = rotation::body_rates(&r, &rd, &rdd);
                let (w, wd) = (rotation * wb, rotation * wdb);
                let (roll, pitch, yaw) = rotation.euler_angles();
                out.goal[g..g + 3].copy_from_slice(&[roll, pitch, yaw]);
                out.velocity[g..g + 3].copy_from_slice(w.as_slice());
                out.acceleration[g..g + 3].copy_from_slice(wd.as_slice());
                i += 3;
                g += 3;
                rot += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests;
