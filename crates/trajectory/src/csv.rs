//! The file format: a header row, then rows `t, c1, c2, …` — t in s from 0,
//! strictly increasing; the columns of each block (a vector's values, an
//! orientation's unit quaternion w x y z). Empty lines and lines starting with
//! `#` are skipped. Every refusal names the line and the reason.

use crate::{Block, TrajectoryError};

/// The rows (t and the columns) of `text` for `blocks`, quaternions normalised.
/// Each row as (its line, t, the columns).
pub(crate) fn rows(
    text: &str,
    blocks: &[Block],
) -> Result<Vec<(usize, f64, Vec<f64>)>, TrajectoryError> {
    let columns: usize = blocks.iter().map(Block::columns).sum();
    let mut out: Vec<(usize, f64, Vec<f64>)> = Vec::new();
    let mut header = false;
    for (index, line) in text.lines().enumerate() {
        let row = index + 1;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if !header {
            if fields.iter().all(|f| f.parse::<f64>().is_ok()) {
                return Err(TrajectoryError::at(
                    row,
                    "the first row must be a header (t, then the columns' names)".into(),
                ));
            }
            if fields.len() != 1 + columns {
                return Err(TrajectoryError::at(
                    row,
                    format!(
                        "the header has {} columns, this level needs {} (t and {})",
                        fields.len(),
                        1 + columns,
                        describe(blocks)
                    ),
                ));
            }
            header = true;
            continue;
        }
        if fields.len() != 1 + columns {
            return Err(TrajectoryError::at(
                row,
                format!(
                    "{} columns, expected {} (t and {})",
                    fields.len(),
                    1 + columns,
                    describe(blocks)
                ),
            ));
        }
        let mut values = Vec::with_capacity(fields.len());
        for (c, f) in fields.iter().enumerate() {
            let x: f64 = f.parse().map_err(|_| {
                TrajectoryError::at(row, format!("column {} is not a number: {f:?}", c + 1))
            })?;
            if !x.is_finite() {
                return Err(TrajectoryError::at(
                    row,
                    format!("column {} is not finite ({f})", c + 1),
                ));
            }
            values.push(x);
        }
        let t = values.remove(0);
        match out.last() {
            None if t != 0.0 => {
                return Err(TrajectoryError::at(
                    row,
                    format!("the first row must be at t = 0, not {t}"),
                ));
            }
            Some((_, prev, _)) if t <= *prev => {
                return Err(TrajectoryError::at(
                    row,
                    format!("t = {t} does not increase (the row before is at t = {prev})"),
                ));
            }
            _ => {}
        }
        normalise_quaternions(&mut values, blocks, row)?;
        out.push((row, t, values));
    }
    if out.is_empty() {
        return Err(TrajectoryError::at(0, "no rows after the header".into()));
    }
    Ok(out)
}

/// Normalises each orientation block's quaternion; an error for one whose
/// norm is not within [`crate::UNIT_TOLERANCE`] of 1.
fn normalise_quaternions(
    values: &mut [f64],
    blocks: &[Block],
    row: usize,
) -> Result<(), TrajectoryError> {
    let mut c = 0;
    for b in blocks {
        if let Block::Rotation = b {
            let q = &mut values[c..c + 4];
            let Some(unit) = crate::unit_quaternion(q) else {
                let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
                return Err(TrajectoryError::at(
                    row,
                    format!(
                        "columns {}–{} are not a unit quaternion w x y z (norm {norm:.6})",
                        c + 2,
                        c + 5
                    ),
                ));
            };
            q.copy_from_slice(&[unit.w, unit.i, unit.j, unit.k]);
        }
        c += b.columns();
    }
    Ok(())
}

/// "x y z", "the quaternion w x y z", … of a level's blocks.
fn describe(blocks: &[Block]) -> String {
    blocks
        .iter()
        .map(|b| match b {
            Block::Vector(k) => format!("{k} values"),
            Block::Rotation => "a quaternion w x y z".to_string(),
        })
        .collect::<Vec<_>>()
        .join(", ")
}
