//! `[contact]`: the defaults, explicit values, and malformed values refused
//! with an error that names the field.

use hcc_config::Scenario;
use hcc_spec::contact::{
    DEFAULT_HOLD_DAMPING, DEFAULT_OBSERVER_GAIN, DEFAULT_RAMP_S, DEFAULT_RELEASE,
    DEFAULT_SOFTEN_FRACTION, DEFAULT_THRESHOLD, Reaction,
};
use std::path::PathBuf;

fn load(extra: &str) -> Result<Scenario, hcc_config::ConfigError> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/paper-sim1.toml");
    let text = std::fs::read_to_string(&path).unwrap() + extra;
    Scenario::from_toml_str(&text, &path)
}

#[test]
fn defaults_without_the_table() {
    let s = load("").unwrap();
    let c = &s.contact;
    assert_eq!(c.observer_gain.len(), 4);
    assert!(c.observer_gain.iter().all(|&k| k == DEFAULT_OBSERVER_GAIN));
    assert!(c.threshold.iter().all(|&t| t == DEFAULT_THRESHOLD));
    assert_eq!(c.release, DEFAULT_RELEASE);
    assert_eq!(c.reaction, Reaction::Report);
    assert_eq!(c.soften_fraction, DEFAULT_SOFTEN_FRACTION);
    assert_eq!(c.ramp_s, DEFAULT_RAMP_S);
    assert!(c.hold_damping.iter().all(|&d| d == DEFAULT_HOLD_DAMPING));
}

#[test]
fn reactions_are_taken() {
    let s =
        load("\n[contact]\nreaction = \"soften\"\nsoften_fraction = 0.3\nramp_s = 0.25\n").unwrap();
    assert_eq!(s.contact.reaction, Reaction::Soften);
    assert_eq!(s.contact.soften_fraction, 0.3);
    assert_eq!(s.contact.ramp_s, 0.25);
    let s =
        load("\n[contact]\nreaction = \"hold\"\nhold_damping = [1.0, 2.0, 3.0, 4.0]\n").unwrap();
    assert_eq!(s.contact.reaction, Reaction::Hold);
    assert_eq!(s.contact.hold_damping.as_slice(), &[1.0, 2.0, 3.0, 4.0]);
    let s = load("\n[contact]\nreaction = \"report\"\n").unwrap();
    assert_eq!(s.contact.reaction, Reaction::Report);
}

#[test]
fn explicit_values_are_taken() {
    let s = load(
        "\n[contact]\nobserver_gain = [50.0, 60.0, 70.0, 80.0]\nthreshold = 3.5\nrelease = 0.25\n",
    )
    .unwrap();
    let c = &s.contact;
    assert_eq!(c.observer_gain.as_slice(), &[50.0, 60.0, 70.0, 80.0]);
    assert!(c.threshold.iter().all(|&t| t == 3.5));
    assert_eq!(c.release, 0.25);
}

#[test]
fn malformed_values_name_the_field() {
    for (text, field, why) in [
        ("observer_gain = 0.0", "contact.observer_gain", "positive"),
        ("observer_gain = -5.0", "contact.observer_gain", "negative"),
        ("observer_gain = nan", "contact.observer_gain", "finite"),
        ("observer_gain = inf", "contact.observer_gain", "finite"),
        (
            "observer_gain = 5000.0",
            "contact.observer_gain",
            "control rate",
        ),
        (
            "observer_gain = [1.0, 2.0]",
            "contact.observer_gain",
            "expected 4",
        ),
        ("threshold = 0.0", "contact.threshold", "positive"),
        (
            "threshold = [1.0, 1.0, 1.0, nan]",
            "contact.threshold[3]",
            "finite",
        ),
        ("threshold = \"high\"", "contact", ""),
        ("release = 0.0", "contact.release", "(0, 1]"),
        ("release = 1.5", "contact.release", "(0, 1]"),
        ("release = nan", "contact.release", "(0, 1]"),
        ("reaction = \"stop\"", "contact", "unknown variant"),
        ("reaction = 1", "contact", ""),
        ("soften_fraction = 0.0", "contact.soften_fraction", "(0, 1]"),
        ("soften_fraction = 1.5", "contact.soften_fraction", "(0, 1]"),
        ("soften_fraction = nan", "contact.soften_fraction", "(0, 1]"),
        ("ramp_s = 0.0", "contact.ramp_s", "positive"),
        ("ramp_s = -1.0", "contact.ramp_s", "positive"),
        ("ramp_s = inf", "contact.ramp_s", "positive"),
        ("hold_damping = 0.0", "contact.hold_damping", "positive"),
        (
            "hold_damping = [1.0, nan, 1.0, 1.0]",
            "contact.hold_damping[1]",
            "finite",
        ),
        (
            "hold_damping = [1.0, 1.0]",
            "contact.hold_damping",
            "expected 4",
        ),
        (
            "reaction = \"hold\"\nhold_damping = 1e6",
            "contact.hold_damping",
            "control rate carries",
        ),
        ("soften = true", "contact", "unknown field"),
    ] {
        let e = load(&format!("\n[contact]\n{text}\n"))
            .err()
            .unwrap_or_else(|| panic!("{text}: loaded without error"));
        let msg = e.to_string();
        assert!(msg.contains(field), "{text}: {msg}");
        assert!(msg.contains(why), "{text}: {msg}");
        assert!(msg.contains("paper-sim1.toml"), "{text}: {msg}");
    }
}
