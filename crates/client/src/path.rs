//! Paths at run time (docs/tracking.md): a level's knots sent on
//! `hcc/<ns>/path`, [`Client::follow`] to begin a path, [`Client::extend_path`]
//! to extend it while it runs (two knots ahead of where it is, at least).
//! Each message is sent once the controller has answered the one before
//! (the controller takes a bounded number of messages per cycle): a refusal
//! names the message's knots.

use std::time::Duration;

use hcc_msgs::{
    MAX_KNOTS_PER_MESSAGE, PATH_EXTEND, PATH_NEW, PathKnots, PathRejection, SetpointAnswer,
};

use crate::{Client, ClientError, rejection};

/// Knots' velocities and accelerations, one entry per knot each.
type Rates<'a> = (&'a [Vec<f64>], &'a [Vec<f64>]);

/// A refusal of one message of a path: its knots, the knot refused when the
/// refusal names one, and why.
#[derive(Debug)]
pub struct KnotsRefused {
    /// The message's first and last knot (0-based in what was sent).
    pub first: usize,
    pub last: usize,
    /// The knot refused (0-based in what was sent), when the refusal is one
    /// knot's (its limits, workspace, order, quaternion, the start).
    pub knot: Option<usize>,
    /// The times of the message's first and last knot.
    pub t_first: f64,
    pub t_last: f64,
    /// The refusal.
    pub error: ClientError,
}

impl KnotsRefused {
    /// The refused knot's time, if the refusal names a knot.
    pub fn t_knot(&self, times: &[f64]) -> Option<f64> {
        self.knot.and_then(|k| times.get(k).copied())
    }
}

impl std::fmt::Display for KnotsRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(k) = self.knot {
            write!(
                f,
                "knot {k} (of the message with knots {}..={}): {}",
                self.first, self.last, self.error
            )
        } else {
            write!(
                f,
                "knots {}..={} (t = {} s … {} s): {}",
                self.first, self.last, self.t_first, self.t_last, self.error
            )
        }
    }
}

impl std::error::Error for KnotsRefused {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.error)
    }
}

impl Client {
    /// Begins a new path on `level` (0-based) with the knots (`times` in s
    /// from 0, `points` in the path file's columns: a position's x y z, an
    /// orientation's quaternion w x y z, a joint level's values), starting in
    /// the cycle of joint state `start_at_state_seq` (0: on receipt). Sends
    /// them in messages of [`MAX_KNOTS_PER_MESSAGE`] (the first begins the
    /// path, the others extend it), each after the answer to the one before
    /// (within `timeout`); returns the last answer.
    pub fn follow(
        &mut self,
        level: usize,
        times: &[f64],
        points: &[Vec<f64>],
        start_at_state_seq: u64,
        timeout: Duration,
    ) -> Result<SetpointAnswer, KnotsRefused> {
        self.send_knots(
            level,
            times,
            points,
            None,
            (true, start_at_state_seq),
            timeout,
        )
    }

    /// [`Client::follow`] with the knots' own velocities and accelerations
    /// (samples, `hcc_msgs::PATH_DERIVATIVES`: the level's goal-velocity
    /// coordinates, an orientation's ω and ω̇ in the base frame; one entry
    /// per knot each).
    pub fn follow_samples(
        &mut self,
        level: usize,
        times: &[f64],
        points: &[Vec<f64>],
        (velocities, accelerations): (&[Vec<f64>], &[Vec<f64>]),
        start_at_state_seq: u64,
        timeout: Duration,
    ) -> Result<SetpointAnswer, KnotsRefused> {
        let rates = Some((velocities, accelerations));
        self.send_knots(
            level,
            times,
            points,
            rates,
            (true, start_at_state_seq),
            timeout,
        )
    }

    /// Extends `level`'s running path with the knots (later than its last).
    pub fn extend_path(
        &mut self,
        level: usize,
        times: &[f64],
        points: &[Vec<f64>],
        timeout: Duration,
    ) -> Result<SetpointAnswer, KnotsRefused> {
        self.send_knots(level, times, points, None, (false, 0), timeout)
    }

    fn send_knots(
        &mut self,
        level: usize,
        times: &[f64],
        points: &[Vec<f64>],
        rates: Option<Rates<'_>>,
        (new, start_at_state_seq): (bool, u64),
        timeout: Duration,
    ) -> Result<SetpointAnswer, KnotsRefused> {
        let refused_at =
            |first: usize, last: usize, knot: Option<usize>, error: ClientError| KnotsRefused {
                first,
                last,
                knot: knot.map(|k| first + k),
                t_first: times.get(first).copied().unwrap_or(f64::NAN),
                t_last: times.get(last).copied().unwrap_or(f64::NAN),
                error,
            };
        let refused = |first, last, error| refused_at(first, last, None, error);
        let rates_fit = rates.is_none_or(|(v, a)| v.len() == times.len() && a.len() == times.len());
        if times.is_empty() || times.len() != points.len() || !rates_fit {
            let e =
                ClientError::PathInvalid(hcc_msgs::KnotsRejection::Path(PathRejection::KnotCount));
            return Err(refused(0, times.len().saturating_sub(1), e));
        }
        let mut answer = None;
        for (chunk, (ts, ps)) in times
            .chunks(MAX_KNOTS_PER_MESSAGE)
            .zip(points.chunks(MAX_KNOTS_PER_MESSAGE))
            .enumerate()
        {
            let (first, last) = (
                chunk * MAX_KNOTS_PER_MESSAGE,
                chunk * MAX_KNOTS_PER_MESSAGE + ts.len() - 1,
            );
            let mut m = PathKnots::zeroed();
            m.client_id = self.client_id;
            m.level = level as u32;
            m.flags = if new && chunk == 0 {
                PATH_NEW
            } else {
                PATH_EXTEND
            };
            m.apply_at_state_seq = start_at_state_seq;
            for (k, (t, p)) in ts.iter().zip(ps).enumerate() {
                let pushed = match rates {
                    Some((v, a)) => m.push_sample(*t, p, &v[first + k], &a[first + k]),
                    None => m.push(*t, p),
                };
                pushed.map_err(|r| {
                    refused_at(
                        first,
                        last,
                        Some(k),
                        ClientError::PathInvalid(hcc_msgs::KnotsRejection::Path(r)),
                    )
                })?;
            }
            m.validate().map_err(|r| {
                refused_at(first, last, r.knot, ClientError::PathInvalid(r.rejection))
            })?;
            self.seq += 1;
            m.header.seq = self.seq;
            m.header.stamp_ns = hcc_msgs::monotonic_now_ns();
            self.paths
                .send_copy(m)
                .map_err(|e| refused(first, last, ClientError::Send(format!("{e:?}"))))?;
            let seq = self.seq;
            let a = self
                .wait_for_answer(seq, timeout)
                .map_err(|e| refused(first, last, e))?;
            if a.code != hcc_msgs::ANSWER_ACCEPTED {
                return Err(refused_at(first, last, a.refused_knot(), rejection(a.code)));
            }
            answer = Some(a);
        }
        answer.ok_or_else(|| refused(0, 0, ClientError::Timeout("no knots sent".into())))
    }
}
