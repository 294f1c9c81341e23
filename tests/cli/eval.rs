//! `railfuse eval` and the accuracy `refuse` prints: against truth, another pipeline or a GNSS
//! receiver, and the same figures in the pass as from the written file.

use super::*;

#[test]
fn eval_scores_against_truth_another_pipeline_or_a_gnss_receiver() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "3", "--duration", "200"], &raw);
    refuse(&raw, "kalman.toml", &fused);
    let eval = |reference: &str| -> serde_json::Value {
        ok_json(&["eval", s(&fused), "--reference", reference, "--json"])
    };
    let truth = eval("/truth");
    let kalman = &truth["pipelines"][0];
    assert!(
        kalman["position_error_m"]["rmse"].as_f64().unwrap() < 1.0,
        "{kalman}"
    );
    // The default run's correction-link outage (120–165 s) is a marked window.
    let w = kalman["windows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["label"] == "no RTK corrections")
        .expect("the outage window");
    assert!(
        w["position_error_m"]["samples"].as_u64().unwrap() > 100,
        "{w}"
    );
    // Against the RTK receiver, matched on the track map: metres at worst (single fixes in the
    // outage), far from the kilometres a wrong projection would give.
    let gnss = eval("/gnss/fix");
    assert_eq!(gnss["reference"], "/gnss/fix");
    assert!(
        gnss["pipelines"][0]["position_error_m"]["rmse"]
            .as_f64()
            .unwrap()
            < 3.0,
        "{}",
        gnss["pipelines"][0]
    );
    let table = String::from_utf8(ok(&["eval", s(&fused)]).stdout).unwrap();
    assert!(
        table.contains("NEES in 95%") && table.contains("in no RTK corrections"),
        "{table}"
    );
}

#[test]
fn the_accuracy_refuse_prints_in_its_pass_equals_eval_of_the_written_file() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("s0.mcap"), d.path().join("s0.fused.mcap"));
    simulate(&["--scenario", "seed000", "--seed", "3"], &raw);
    let cfg = sample("seed000.toml"); // kf_balise has an RTS smoother
    let o = ok(&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&fused), "--json"]);
    let in_pass: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let o = ok(&["eval", s(&fused), "--json"]);
    let from_file: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (a, b) = (&in_pass["eval"]["pipelines"], &from_file["pipelines"]);
    assert!(
        a.as_array()
            .unwrap()
            .iter()
            .any(|p| p["name"] == "kf_balise/smoothed"),
        "{a}"
    );
    // The same states and counts; figures equal but for the last bits: the file's JSON floats
    // are parsed by serde_json's fast parser (within an ulp), the in-pass ones never left f64.
    let worst = differ(a, b);
    assert!(
        worst < 1e-9,
        "in-pass and file evaluations differ by {worst}:\n{a}\n{b}"
    );
    assert_eq!(in_pass["eval"]["windows"], from_file["windows"]);
}

/// The largest relative difference between two JSON documents of the same shape (∞ where
/// the shapes or any non-number differ).
fn differ(a: &serde_json::Value, b: &serde_json::Value) -> f64 {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            (x - y).abs() / x.abs().max(y.abs()).max(1e-300)
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .map(|(x, y)| differ(x, y))
            .fold(0.0, f64::max),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => x
            .iter()
            .map(|(k, v)| y.get(k).map_or(f64::INFINITY, |w| differ(v, w)))
            .fold(0.0, f64::max),
        _ if a == b => 0.0,
        _ => f64::INFINITY,
    }
}
