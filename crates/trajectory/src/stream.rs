//! A path that arrives while it runs — a planner's knots in messages that
//! extend it, a device's samples at up to the control rate: knots appended to
//! a preallocated ring and interpolated C² from local data only, so that
//! nothing already executing ever changes.
//!
//! Each knot k has its coordinates y_k (an orientation as its rotation
//! vector relative to the first knot's, as in [`crate::Trajectory`]) and a
//! velocity and acceleration per coordinate, from its neighbours by the
//! three-point formulas of a non-uniform grid,
//!
//! v_k = (h₀² Δ₁ + h₁² Δ₀) / (h₀ h₁ (h₀ + h₁)),  a_k = 2 (h₀ Δ₁ − h₁ Δ₀) / (h₀ h₁ (h₀ + h₁)),
//!
//! Δ₀ = y_k − y_{k−1}, Δ₁ = y_{k+1} − y_k, h₀, h₁ the two intervals. The
//! first knot is at rest. A **sample** ([`PathStream::push_sample`]) brings
//! its own velocity and acceleration instead (an orientation's angular
//! velocity ω and acceleration ω̇ in the base frame, turned into the rotation
//! vector's rates by the inverse right Jacobian: ṙ = J_r⁻¹ Rᵀω,
//! r̈ = J_r⁻¹ (Rᵀω̇ − J̇_r ṙ)). Each segment is the quintic Hermite polynomial
//! between the states (y, v, a) of its two knots (C² across knots), and is
//! fixed when the path enters it: later knots change only segments not yet
//! begun.
//!
//! **Lookahead and the stop.** Entering the segment from knot k to k + 1
//! needs knot k + 2 (for k + 1's derivatives) unless k + 1 is a sample.
//! Without it the path stops: the segment ends at rest on knot k + 1,
//! stretched to at least 3 max|v_k| / `stop_deceleration` s so that it
//! decelerates smoothly (it may pass the knot and come back to it), and the
//! path has ended — further knots are refused. Past its last knot with
//! nothing after (a stream of samples that stops, or a path of one knot), the
//! path comes to rest on that knot the same way. A stream therefore keeps two
//! knots, or one sample, ahead of where the path is. Allocation-free after
//! [`PathStream::new`].

use crate::{Block, MAX_TURN, PathSample, spline};
use nalgebra::UnitQuaternion;

/// Why a knot was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KnotError {
    /// Its time does not come after the last knot's.
    #[error("its time does not come after the previous knot's")]
    NotIncreasing,
    /// A value is not finite, or the columns do not fit the level.
    #[error("a value is not finite or the knot has the wrong number of columns")]
    Malformed,
    /// A quaternion is not a unit quaternion.
    #[error("a quaternion w x y z is not a unit quaternion")]
    NotUnit,
    /// An orientation turns more than [`MAX_TURN`] from the first knot's.
    #[error("an orientation turns more than 0.9π from the path's first")]
    Turn,
    /// The ring holds as many knots ahead as it can.
    #[error("the path holds as many knots ahead as it can")]
    Full,
    /// The path has stopped (it ran out of knots): send a new path.
    #[error("the path has ended: send a new path")]
    Ended,
}

/// The path's state, for telemetry and answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamState {
    /// No knot yet.
    Empty,
    /// Moving through its knots.
    Running,
    /// In its stopping segment (it ran out of knots, or reached its last).
    Stopping,
    /// At rest on its last knot.
    Done,
}

/// The shortest stop, s (a stop from rest on the knot it is at).
const MIN_STOP_S: f64 = 1e-3;
/// A stop sheds an acceleration as large as its deceleration over this
/// long, s (a jerk of at most `stop_deceleration` per s).
const SHED_S: f64 = 1.0;

/// The segment being executed.
#[derive(Clone, Debug)]
struct Segment {
    /// Absolute index of its first knot.
    k: u64,
    t0: f64,
    h: f64,
    /// The stopping segment (to the last knot known when it began).
    stop: bool,
}

/// A path extended while it runs.
#[derive(Clone, Debug)]
pub struct PathStream {
    blocks: Vec<Block>,
    /// Interpolated coordinates per knot.
    c: usize,
    capacity: usize,
    /// The ring: time, coordinates (c per knot), a sample's velocity and
    /// acceleration in the coordinates (c per knot) and whether it is one.
    t: Vec<f64>,
    y: Vec<f64>,
    yd: Vec<f64>,
    ydd: Vec<f64>,
    given: Vec<bool>,
    /// Absolute index of the oldest knot kept, and how many are kept.
    first: u64,
    len: usize,
    references: Vec<UnitQuaternion<f64>>,
    segment: Option<Segment>,
    /// Its coefficients (c) and its end state (v, a per coordinate), which
    /// the next segment starts from.
    coeffs: Vec<spline::Quintic>,
    end_v: Vec<f64>,
    end_a: Vec<f64>,
    start_v: Vec<f64>,
    start_a: Vec<f64>,
    scratch: Vec<f64>,
    stop_deceleration: f64,
}

impl PathStream {
    /// A path of `blocks` holding up to `capacity` (≥ 3) knots at once;
    /// `stop_deceleration` (> 0, units of the coordinates per s²) sets how
    /// slowly it stops when it runs out of knots.
    pub fn new(blocks: &[Block], capacity: usize, stop_deceleration: f64) -> PathStream {
        let c: usize = blocks.iter().map(Block::dim).sum();
        let capacity = capacity.max(3);
        let rotations = blocks.iter().filter(|b| **b == Block::Rotation).count();
        PathStream {
            blocks: blocks.to_vec(),
            c,
            capacity,
            t: vec![0.0; capacity],
            y: vec![0.0; capacity * c],
            yd: vec![0.0; capacity * c],
            ydd: vec![0.0; capacity * c],
            given: vec![false; capacity],
            first: 0,
            len: 0,
            references: vec![UnitQuaternion::identity(); rotations],
            segment: None,
            coeffs: vec![[0.0; 6]; c],
            end_v: vec![0.0; c],
            end_a: vec![0.0; c],
            start_v: vec![0.0; c],
            start_a: vec![0.0; c],
            scratch: vec![0.0; c],
            stop_deceleration: if stop_deceleration > 0.0 {
                stop_deceleration
            } else {
                1.0
            },
        }
    }

    /// The columns of one knot in the file format of [`crate::Trajectory`].
    pub fn columns(&self) -> usize {
        self.blocks.iter().map(Block::columns).sum()
    }

    /// Empties the path (a new one begins with the next knot).
    pub fn clear(&mut self) {
        self.first = 0;
        self.len = 0;
        self.segment = None;
    }

    /// Where the path is.
    pub fn state(&self, t: f64) -> StreamState {
        match &self.segment {
            _ if self.len == 0 => StreamState::Empty,
            Some(s) if s.stop && t >= s.t0 + s.h => StreamState::Done,
            Some(s) if s.stop => StreamState::Stopping,
            _ => StreamState::Running,
        }
    }

    /// How many knots it holds (those not yet passed).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds no knot.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Drops the knots appended after it held `len` (a batch refused
    /// part-way is taken back whole). Only knots no segment has entered.
    pub fn truncate(&mut self, len: usize) {
        let entered = self
            .segment
            .as_ref()
            .map_or(0, |s| (s.k + 2 - self.first) as usize);
        self.len = self.len.min(len.max(entered));
    }

    /// How many more knots it holds now.
    pub fn room(&self) -> usize {
        self.capacity - self.len
    }

    /// The time of the last knot, if any.
    pub fn last_time(&self) -> Option<f64> {
        (self.len > 0).then(|| self.t[self.slot(self.first + self.len as u64 - 1)])
    }

    fn slot(&self, k: u64) -> usize {
        (k % self.capacity as u64) as usize
    }

    /// Appends a knot at path time `t` with `columns` (a vector's values, an
    /// orientation's unit quaternion w x y z). Allocation-free.
    pub fn push(&mut self, t: f64, columns: &[f64]) -> Result<(), KnotError> {
        self.push_knot(t, columns, None)
    }

    /// Appends a sample: a knot with its `velocity` and `acceleration` in
    /// the goal's coordinates (a vector's rates, an orientation's ω and ω̇
    /// in the base frame; [`PathSample`]'s layout). Allocation-free.
    pub fn push_sample(
        &mut self,
        t: f64,
        columns: &[f64],
        velocity: &[f64],
        acceleration: &[f64],
    ) -> Result<(), KnotError> {
        let m = self.sample_dim();
        if velocity.len() != m
            || acceleration.len() != m
            || velocity.iter().chain(acceleration).any(|x| !x.is_finite())
        {
            return Err(KnotError::Malformed);
        }
        self.push_knot(t, columns, Some((velocity, acceleration)))
    }

    /// The goal's dimension (a [`PathSample`]'s vectors, a sample's
    /// velocity and acceleration).
    pub fn sample_dim(&self) -> usize {
        self.c
    }

    fn push_knot(
        &mut self,
        t: f64,
        columns: &[f64],
        rates: Option<(&[f64], &[f64])>,
    ) -> Result<(), KnotError> {
        if self.segment.as_ref().is_some_and(|s| s.stop) {
            return Err(KnotError::Ended);
        }
        if columns.len() != self.columns()
            || !t.is_finite()
            || columns.iter().any(|x| !x.is_finite())
        {
            return Err(KnotError::Malformed);
        }
        if self.last_time().is_some_and(|last| t <= last) {
            return Err(KnotError::NotIncreasing);
        }
        if self.len == self.capacity {
            return Err(KnotError::Full);
        }
        // Coordinates first (a refusal changes nothing).
        let first = self.len == 0;
        let (mut col, mut i, mut rot) = (0, 0, 0);
        for b in &self.blocks {
            match b {
                Block::Vector(n) => {
                    self.scratch[i..i + n].copy_from_slice(&columns[col..col + n]);
                    i += n;
                }
                Block::Rotation => {
                    let q =
                        crate::unit_quaternion(&columns[col..col + 4]).ok_or(KnotError::NotUnit)?;
                    // A new path's first knot is its orientations' reference
                    // (set even if a later block is refused: the path is
                    // empty then, and the next first knot sets it again).
                    if first {
                        self.references[rot] = q;
                    }
                    let r0 = self.references[rot];
                    let r = (r0.inverse() * q).scaled_axis();
                    if r.norm() > MAX_TURN {
                        return Err(KnotError::Turn);
                    }
                    self.scratch[i..i + 3].copy_from_slice(r.as_slice());
                    i += 3;
                    rot += 1;
                }
            }
            col += b.columns();
        }
        let s = self.slot(self.first + self.len as u64);
        let range = s * self.c..(s + 1) * self.c;
        if let Some((velocity, acceleration)) = rates {
            self.coordinate_rates(velocity, acceleration, range.clone())?;
        }
        self.t[s] = t;
        self.y[range].copy_from_slice(&self.scratch);
        self.given[s] = rates.is_some();
        self.len += 1;
        Ok(())
    }

    /// A sample's rates in the interpolated coordinates (the knot's
    /// coordinates in `scratch`) into the ring's `range`.
    fn coordinate_rates(
        &mut self,
        velocity: &[f64],
        acceleration: &[f64],
        range: std::ops::Range<usize>,
    ) -> Result<(), KnotError> {
        let (mut i, mut rot) = (0, 0);
        let (yd, ydd) = (&mut self.yd[range.clone()], &mut self.ydd[range]);
        for b in &self.blocks {
            match b {
                Block::Vector(n) => {
                    yd[i..i + n].copy_from_slice(&velocity[i..i + n]);
                    ydd[i..i + n].copy_from_slice(&acceleration[i..i + n]);
                    i += n;
                }
                Block::Rotation => {
                    let r = nalgebra::Vector3::from_column_slice(&self.scratch[i..i + 3]);
                    let rotation = self.references[rot] * UnitQuaternion::from_scaled_axis(r);
                    let w = rotation.inverse_transform_vector(
                        &nalgebra::Vector3::from_column_slice(&velocity[i..i + 3]),
                    );
                    let wd = rotation.inverse_transform_vector(
                        &nalgebra::Vector3::from_column_slice(&acceleration[i..i + 3]),
                    );
                    let (rd, rdd) =
                        crate::rotation::coordinate_rates(&r, &w, &wd).ok_or(KnotError::Turn)?;
                    yd[i..i + 3].copy_from_slice(rd.as_slice());
                    ydd[i..i + 3].copy_from_slice(rdd.as_slice());
                    i += 3;
                    rot += 1;
                }
            }
        }
        Ok(())
    }

    /// Knot k's coordinate i.
    fn yk(&self, k: u64, i: usize) -> f64 {
        self.y[self.slot(k) * self.c + i]
    }

    fn tk(&self, k: u64) -> f64 {
        self.t[self.slot(k)]
    }

    /// Knot k's velocity and acceleration in coordinate i, if it is a sample.
    fn rates(&self, k: u64, i: usize) -> Option<(f64, f64)> {
        let s = self.slot(k);
        self.given[s].then(|| (self.yd[s * self.c + i], self.ydd[s * self.c + i]))
    }

    /// Enters the segment from knot `k` (kept) to k + 1, starting from
    /// `start_v`, `start_a`; its end state from k + 1's sample, from k + 2,
    /// or a stop (to rest on k + 1, or on k itself when it is the last).
    fn enter(&mut self, k: u64) {
        // Knots before k are no longer needed.
        let drop = k.saturating_sub(self.first) as usize;
        self.first += drop as u64;
        self.len -= drop.min(self.len);
        let last = self.first + self.len as u64 - 1;
        let end = (k + 1).min(last);
        let t0 = self.tk(k);
        let mut h = self.tk(end) - t0;
        let sample = end > k && self.given[self.slot(end)];
        let stop = !sample && end + 1 > last;
        if sample {
            for i in 0..self.c {
                (self.end_v[i], self.end_a[i]) = self.rates(end, i).unwrap_or((0.0, 0.0));
            }
        } else if stop {
            self.end_v.fill(0.0);
            self.end_a.fill(0.0);
            let v = self.start_v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            let a = self.start_a.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            // Long enough to shed the velocity at about the stop's
            // deceleration and the acceleration at its jerk, never empty.
            h = h
                .max(3.0 * v / self.stop_deceleration)
                .max(SHED_S * a / self.stop_deceleration)
                .max(MIN_STOP_S);
        } else {
            let (h0, h1) = (h, self.tk(k + 2) - self.tk(k + 1));
            for i in 0..self.c {
                let (d0, d1) = (
                    self.yk(k + 1, i) - self.yk(k, i),
                    self.yk(k + 2, i) - self.yk(k + 1, i),
                );
                let den = h0 * h1 * (h0 + h1);
                self.end_v[i] = (h0 * h0 * d1 + h1 * h1 * d0) / den;
                self.end_a[i] = 2.0 * (h0 * d1 - h1 * d0) / den;
            }
        }
        for i in 0..self.c {
            self.coeffs[i] = spline::hermite(
                h,
                [self.yk(k, i), self.start_v[i], self.start_a[i]],
                [self.yk(end, i), self.end_v[i], self.end_a[i]],
            );
        }
        self.segment = Some(Segment { k, t0, h, stop });
    }

    /// The desired value at path time `t` into `out` (from
    /// [`PathStream::sample_buffer`]): before the first segment and with a
    /// single knot, the first knot at rest; after the stop, the last knot at
    /// rest. Allocation-free.
    pub fn sample(&mut self, t: f64, out: &mut PathSample) {
        if self.len == 0 {
            return;
        }
        // The first segment: from the first knot at rest, or with its
        // sample's rates; a path of one knot that time has passed stops.
        let single_passed = self.len == 1 && t > self.tk(self.first);
        if self.segment.is_none() && (self.len >= 2 || single_passed) && t >= self.tk(self.first) {
            for i in 0..self.c {
                (self.start_v[i], self.start_a[i]) =
                    self.rates(self.first, i).unwrap_or((0.0, 0.0));
            }
            self.enter(self.first);
        }
        while let Some(s) = &self.segment {
            if s.stop || t < s.t0 + s.h {
                break;
            }
            let next = s.k + 1;
            std::mem::swap(&mut self.start_v, &mut self.end_v);
            std::mem::swap(&mut self.start_a, &mut self.end_a);
            self.enter(next);
        }
        let (segment, coeffs, first) = (&self.segment, &self.coeffs, self.first);
        let k0 = self.slot(first) * self.c;
        let y0 = &self.y[k0..k0 + self.c];
        let coord = |i: usize| -> [f64; 3] {
            match segment {
                None => [y0[i], 0.0, 0.0],
                Some(s) => {
                    let u = ((t - s.t0) / s.h).clamp(0.0, 1.0);
                    let [p, v, a] = spline::evaluate(&coeffs[i], s.h, u);
                    if t >= s.t0 + s.h {
                        [p, 0.0, 0.0]
                    } else {
                        [p, v, a]
                    }
                }
            }
        };
        crate::assemble(&self.blocks, &self.references, coord, out);
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
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5 cm circle in y-z at 0.25 Hz, a knot every `dt` s for `n` knots.
    fn circle(k: usize, dt: f64) -> (f64, [f64; 3]) {
        let t = k as f64 * dt;
        let w = 2.0 * std::f64::consts::PI * 0.25;
        (t, [0.4, 0.05 * (w * t).sin(), 0.4 + 0.05 * (w * t).cos()])
    }

    fn run(stream: &mut PathStream, until: f64) -> Vec<PathSample> {
        let mut out = Vec::new();
        let mut s = stream.sample_buffer();
        for k in 0..=(until * 1000.0) as usize {
            stream.sample(k as f64 * 1e-3, &mut s);
            out.push(s.clone());
        }
        out
    }

    #[test]
    fn knots_streamed_two_ahead_give_the_path_sent_at_once_bit_for_bit() {
        let blocks = [Block::Vector(3)];
        let mut whole = PathStream::new(&blocks, 256, 1.0);
        for k in 0..=100 {
            let (t, p) = circle(k, 0.05);
            whole.push(t, &p).unwrap();
        }
        let a = run(&mut whole, 6.0);
        // Streamed: each knot pushed two knots before the path needs it.
        let mut streamed = PathStream::new(&blocks, 8, 1.0);
        let mut s = streamed.sample_buffer();
        let mut next = 0;
        let mut b = Vec::new();
        for step in 0..=6000 {
            let t = step as f64 * 1e-3;
            while next <= 100 && circle(next, 0.05).0 <= t + 0.12 {
                let (tk, p) = circle(next, 0.05);
                streamed.push(tk, &p).unwrap();
                next += 1;
            }
            streamed.sample(t, &mut s);
            b.push(s.clone());
        }
        assert_eq!(a, b);
        // On the circle in the middle (3-point derivatives, 50 ms knots).
        let (_, p) = circle(50, 0.05);
        assert!((a[2500].goal[1] - p[1]).abs() < 1e-12);
        let v = 0.05 * 2.0 * std::f64::consts::PI * 0.25;
        let speed = (a[2520].velocity[1].powi(2) + a[2520].velocity[2].powi(2)).sqrt();
        assert!((speed - v).abs() < 1e-3 * v, "{speed} vs {v}");
        // Ends at rest on the last knot.
        assert_eq!(whole.state(6.0), StreamState::Done);
        let (_, last) = circle(100, 0.05);
        assert!((0..3).all(|i| (a[6000].goal[i] - last[i]).abs() < 1e-12));
        assert_eq!(a[6000].velocity, vec![0.0; 3]);
    }

    #[test]
    fn a_stream_that_stops_comes_to_rest_on_its_last_knot_smoothly() {
        let mut p = PathStream::new(&[Block::Vector(3)], 32, 1.0);
        for k in 0..=20 {
            let (t, x) = circle(k, 0.05);
            p.push(t, &x).unwrap();
        }
        let out = run(&mut p, 3.0);
        assert_eq!(p.state(3.0), StreamState::Done);
        assert_eq!(p.push(1.5, &[0.4, 0.0, 0.4]), Err(KnotError::Ended));
        let (_, last) = circle(20, 0.05);
        let end = &out[3000];
        assert!(
            (0..3).all(|i| (end.goal[i] - last[i]).abs() < 1e-12),
            "{end:?}"
        );
        // From the last knots on (the stop from 0.95 s): no velocity step,
        // the deceleration bounded by the stop's.
        let mut worst_dv: f64 = 0.0;
        let mut worst_a: f64 = 0.0;
        for w in out[900..].windows(2) {
            for i in 0..3 {
                worst_dv = worst_dv.max((w[1].velocity[i] - w[0].velocity[i]).abs());
                worst_a = worst_a.max(w[1].acceleration[i].abs());
            }
        }
        println!(
            "stop: largest velocity step per ms {worst_dv:.2e}, largest acceleration {worst_a:.3}"
        );
        assert!(worst_dv < 2e-3 && worst_a <= 1.0, "{worst_dv} {worst_a}");
    }

    #[test]
    fn refusals_change_nothing() {
        let mut p = PathStream::new(&[Block::Vector(1), Block::Rotation], 3, 1.0);
        assert_eq!(p.columns(), 5);
        p.push(0.0, &[0.0, 1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(
            p.push(0.0, &[0.0, 1.0, 0.0, 0.0, 0.0]),
            Err(KnotError::NotIncreasing)
        );
        assert_eq!(
            p.push(0.1, &[0.0, 0.5, 0.0, 0.0, 0.0]),
            Err(KnotError::NotUnit)
        );
        assert_eq!(
            p.push(0.1, &[0.0, 0.0, 0.0, 0.0, 1.0]),
            Err(KnotError::Turn)
        );
        assert_eq!(
            p.push(0.1, &[f64::NAN, 1.0, 0.0, 0.0, 0.0]),
            Err(KnotError::Malformed)
        );
        assert_eq!(p.push(0.1, &[0.0, 1.0]), Err(KnotError::Malformed));
        p.push(0.1, &[0.1, 1.0, 0.0, 0.0, 0.0]).unwrap();
        p.push(0.2, &[0.2, 1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(
            p.push(0.3, &[0.3, 1.0, 0.0, 0.0, 0.0]),
            Err(KnotError::Full)
        );
        assert_eq!(p.last_time(), Some(0.2));
    }
}
