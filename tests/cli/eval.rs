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
fn a_gnss_reference_is_scored_at_its_fixes_of_the_stated_quality() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "3", "--duration", "200"], &raw);
    refuse(&raw, "kalman.toml", &fused);
    let eval = |args: &[&str]| -> serde_json::Value {
        ok_json(&[&["eval", s(&fused), "--json"][..], args].concat())
    };
    let truth = eval(&[]);
    let auto = eval(&["--reference", "/gnss/fix"]);
    let p = &auto["pipelines"][0];
    let f = &p["reference_fixes"];
    // RTK fixed by default, since the receiver has RTK fixed fixes; the rest (its
    // correction outage) left out and counted.
    assert_eq!(f["quality"], "rtk_fixed", "{f}");
    let n = |k: &str| f[k].as_u64().unwrap();
    assert!(n("matched") > 1000 && n("other_quality") > 100, "{f}");
    assert_eq!(
        n("matched") + n("in_state_gaps") + n("outside_states"),
        n("fixes"),
        "{f}"
    );
    // Each fix met by the states interpolated to its time: never further than half the
    // states' spacing from one.
    assert!(f["largest_dt_s"].as_f64().unwrap() <= 0.05, "{f}");
    // The receiver's own errors (multipath near structures, RTK fixed or not) are in the
    // figure, so it is above the truth's, but of its order: not the metres of a wrong match.
    let (against_truth, against_rtk) = (
        truth["pipelines"][0]["position_error_m"]["rmse"]
            .as_f64()
            .unwrap(),
        p["position_error_m"]["rmse"].as_f64().unwrap(),
    );
    assert!(
        against_rtk < against_truth + 1.0,
        "against RTK fixed {against_rtk} m, against the truth {against_truth} m"
    );
    // Every fix counts with `all`: the single and float fixes of the outage make it worse.
    let all = eval(&["--reference", "/gnss/fix", "--reference-quality", "all"]);
    let fa = &all["pipelines"][0]["reference_fixes"];
    assert_eq!(
        fa["fixes"].as_u64().unwrap(),
        n("fixes") + n("other_quality"),
        "{fa}"
    );
    assert!(
        all["pipelines"][0]["position_error_m"]["rmse"]
            .as_f64()
            .unwrap()
            > against_rtk,
        "{all}"
    );
    // A quality the receiver never had: said, not a table of nothing.
    let o = ok(&[
        "eval",
        s(&fused),
        "--reference",
        "/gnss/fix",
        "--reference-quality",
        "dgps",
    ]);
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.contains("kalman: no reference fix of quality dgps on the track"),
        "{text}"
    );
    let text =
        String::from_utf8(ok(&["eval", s(&fused), "--reference", "/gnss/fix"]).stdout).unwrap();
    assert!(
        text.contains("at each reference fix, the states interpolated to its time")
            && text.contains("rtk_fixed fixes matched"),
        "{text}"
    );
    // A Foxglove LocationFix (the fused log's twin of the fixes) serves as well: no fix type
    // and no speed, so every fix counts and the speed columns say why they are empty.
    let fox = eval(&["--reference", "/foxglove/gnss/fix"]);
    let p = &fox["pipelines"][0];
    assert_eq!(p["reference_fixes"]["quality"], "all", "{p}");
    assert!(p["speed_error_mps"].is_null(), "{p}");
    assert_eq!(
        p["reference_fixes"]["no_speed"],
        "the reference carries no speed"
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
