//! `/path`: a client's path knots ([`PathKnots`], docs/tracking.md) as the
//! controller received them, so that a run with paths sent at run time
//! replays bit for bit. Numbers as in every message of a recording
//! (shortest round-trip form; NaN as `null`).

use hcc_msgs::{MAX_KNOTS_PER_MESSAGE, MAX_PATH_COLUMNS, MAX_TASK_DIM, PathKnots};
use serde::{Deserialize, Deserializer, Serialize};

use super::messages::nums;

/// Reads rows of numbers or `null`s (NaN).
fn rows<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<f64>>, D::Error> {
    Ok(Vec::<Vec<Option<f64>>>::deserialize(d)?
        .into_iter()
        .map(|r| r.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect())
        .collect())
}

/// `/path`: one [`PathKnots`] message, its first `count` knots.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PathMsg {
    pub seq: u64,
    pub stamp_ns: u64,
    pub schema_version: u32,
    pub n_joints: u32,
    pub client_id: u64,
    /// 0-based level, as sent.
    pub level: u32,
    /// `PATH_*` bits.
    pub flags: u32,
    pub columns: u32,
    pub count: u32,
    pub apply_at_state_seq: u64,
    /// The knots' times, s.
    #[serde(deserialize_with = "nums")]
    pub t: Vec<f64>,
    /// The knots' values, `columns` each.
    #[serde(deserialize_with = "rows")]
    pub values: Vec<Vec<f64>>,
    /// With `PATH_DERIVATIVES`: the knots' velocities and accelerations
    /// (`columns` entries each, the level's dimension first); empty without.
    #[serde(default, deserialize_with = "rows")]
    pub velocity: Vec<Vec<f64>>,
    #[serde(default, deserialize_with = "rows")]
    pub acceleration: Vec<Vec<f64>>,
}

impl From<&PathKnots> for PathMsg {
    fn from(p: &PathKnots) -> Self {
        let (n, c) = (p.count(), p.columns());
        let d = c.min(MAX_TASK_DIM);
        let derivatives = |a: &[[f64; MAX_TASK_DIM]; MAX_KNOTS_PER_MESSAGE]| {
            if p.has_derivatives() {
                a[..n].iter().map(|r| r[..d].to_vec()).collect()
            } else {
                Vec::new()
            }
        };
        PathMsg {
            seq: p.header.seq,
            stamp_ns: p.header.stamp_ns,
            schema_version: p.header.schema_version,
            n_joints: p.header.n_joints,
            client_id: p.client_id,
            level: p.level,
            flags: p.flags,
            columns: p.columns,
            count: p.count,
            apply_at_state_seq: p.apply_at_state_seq,
            t: p.t[..n].to_vec(),
            values: p.values[..n].iter().map(|r| r[..c].to_vec()).collect(),
            velocity: derivatives(&p.velocity),
            acceleration: derivatives(&p.acceleration),
        }
    }
}

impl PathMsg {
    /// The contract message.
    pub fn to_msg(&self) -> Result<PathKnots, String> {
        let mut p = PathKnots::zeroed();
        p.header.seq = self.seq;
        p.header.stamp_ns = self.stamp_ns;
        p.header.schema_version = self.schema_version;
        p.header.n_joints = self.n_joints;
        p.client_id = self.client_id;
        p.level = self.level;
        p.flags = self.flags;
        p.columns = self.columns;
        p.count = self.count;
        p.apply_at_state_seq = self.apply_at_state_seq;
        let too_many = |what: &str, n: usize| {
            format!("path: {n} {what}, the capacity is {MAX_KNOTS_PER_MESSAGE}")
        };
        if self.t.len() > MAX_KNOTS_PER_MESSAGE {
            return Err(too_many("times", self.t.len()));
        }
        p.t[..self.t.len()].copy_from_slice(&self.t);
        let fill = |dst: &mut [[f64; MAX_PATH_COLUMNS]; MAX_KNOTS_PER_MESSAGE],
                    src: &[Vec<f64>],
                    what: &str|
         -> Result<(), String> {
            if src.len() > MAX_KNOTS_PER_MESSAGE {
                return Err(too_many(what, src.len()));
            }
            for (d, s) in dst.iter_mut().zip(src) {
                if s.len() > d.len() {
                    return Err(format!("path: a knot's {what} has {} entries", s.len()));
                }
                d[..s.len()].copy_from_slice(s);
            }
            Ok(())
        };
        fill(&mut p.values, &self.values, "values")?;
        fill(&mut p.velocity, &self.velocity, "velocity")?;
        fill(&mut p.acceleration, &self.acceleration, "acceleration")?;
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hcc_msgs::{PATH_EXTEND, PATH_NEW};

    #[test]
    fn knots_and_samples_round_trip_bit_for_bit() {
        let mut p = PathKnots::zeroed();
        p.flags = PATH_NEW;
        p.client_id = 7;
        p.header.seq = 3;
        p.apply_at_state_seq = 120;
        for k in 0..5 {
            let t = 0.1 * k as f64 + 1e-17;
            p.push(t, &[0.4 + t.sin() / 3.0, -0.1, 1.0 / 7.0]).unwrap();
        }
        let mut s = PathKnots::zeroed();
        s.flags = PATH_EXTEND;
        s.push_sample(
            0.7,
            &[1.0, 0.0, 0.0, 0.0],
            &[0.1, 0.2, 1.0 / 3.0],
            &[1e-300, 0.0, -2.5],
        )
        .unwrap();
        for m in [p, s] {
            let json = serde_json::to_string(&PathMsg::from(&m)).unwrap();
            let back: PathMsg = serde_json::from_str(&json).unwrap();
            assert_eq!(back.to_msg().unwrap(), m, "{json}");
        }
    }
}
