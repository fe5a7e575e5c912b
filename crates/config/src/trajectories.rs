//! `[[level]] trajectory = "FILE.csv"` and `feed_forward` (docs/tracking.md):
//! each level's path read relative to the scenario and checked
//! (`hcc_trajectory`: rows, t, columns, unit quaternions), its first row the
//! level's goal; errors name the field, its line, the CSV file and its row.

use hcc_spec::tracking::{LevelPath, Tracking, blocks};
use hcc_spec::{Form, LevelSpec};
use hcc_trajectory::Trajectory;
use nalgebra::DVector;
use std::collections::BTreeMap;

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema::LevelSection;

/// The levels' paths and feed-forward flags; sets each path level's goal to
/// its first row. A file's text is `texts`' where it holds the file (a
/// recording's, a controller's document's), else the file's.
pub(crate) fn resolve_tracking(
    cx: &Ctx,
    sections: &[LevelSection],
    levels: &mut [LevelSpec],
    n: usize,
    form: Form,
    texts: &BTreeMap<String, String>,
) -> Result<Tracking, ConfigError> {
    let mut tracking = Tracking::default();
    for (i, (l, spec)) in sections.iter().zip(levels.iter_mut()).enumerate() {
        let feed_forward = l.feed_forward.unwrap_or(true);
        tracking.feed_forward.push(feed_forward);
        let Some(file) = &l.trajectory else {
            tracking.paths.push(None);
            continue;
        };
        let field = format!("level[{i}].trajectory");
        if feed_forward && form != Form::Extended {
            return Err(cx.err(
                &field,
                "the tracking feed-forward is the extended form's (controller.form = \
                 \"extended\"); or set feed_forward = false for this level",
            ));
        }
        let text = match texts.get(file) {
            Some(t) => t.clone(),
            None => {
                let base = cx.file.parent().unwrap_or(std::path::Path::new("."));
                std::fs::read_to_string(base.join(file))
                    .map_err(|e| cx.err(&field, format!("{file}: cannot be read ({e})")))?
            }
        };
        let trajectory = Trajectory::parse(&text, &blocks(&spec.tasks, n))
            .map_err(|e| cx.err(&field, format!("{file}: {e}")))?;
        let mut first = trajectory.sample_buffer();
        trajectory.sample(0.0, &mut first);
        spec.goal = DVector::from_vec(first.goal);
        tracking.paths.push(Some(LevelPath {
            file: file.clone(),
            text,
            trajectory,
        }));
    }
    Ok(tracking)
}
