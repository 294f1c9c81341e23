use super::*;
use crate::config::FromMessage;
use crate::filter::sharing::SharingTable;

const GOOD: &str = r#"
[[pipeline]]
name = "kf"
filter = "kalman"
motion = { model = "constant_acceleration", jerk_psd = 0.05 }

[[pipeline.sensor]]
topic = "/loop/position"
variance = "message"

[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.01
gate_nis = 16.0
"#;

fn err(text: &str) -> String {
    Pipelines::parse(text, Path::new("p.toml"))
        .unwrap_err()
        .to_string()
}

#[test]
fn a_good_config_parses_and_round_trips() {
    let c = Pipelines::parse(GOOD, Path::new("p.toml")).unwrap();
    assert_eq!(
        c.pipeline[0].sensors[0].variance,
        Variance::FromMessage(FromMessage::Message)
    );
    assert_eq!(c.pipeline[0].sensors[1].variance, Variance::Fixed(0.01));
    assert_eq!(c.pipeline[0].sensors[1].gate_nis, Some(16.0));
    let toml = c.pipeline[0].to_toml();
    let again = Pipelines::parse(&toml, Path::new("x")).unwrap();
    assert_eq!(again.pipeline[0].to_toml(), toml);
    assert_eq!(c.pipeline[0].sensors[1].declared.line, 11);
}

#[test]
fn an_unknown_key_is_named_with_its_line_and_column() {
    let e = err(&GOOD.replace("gate_nis = 16.0", "gate_nsi = 16.0"));
    assert!(
        e.starts_with("p.toml: line 14, column 1: unknown field `gate_nsi`"),
        "{e}"
    );
}

#[test]
fn a_wrong_type_is_named_with_its_line() {
    let e = err(&GOOD.replace("variance = 0.01", "variance = [1]"));
    assert!(
        e.contains("line 13, column 12") && e.contains("a variance"),
        "{e}"
    );
}

#[test]
fn invalid_values_are_refused_with_the_line_of_their_table_and_the_pipeline_name() {
    let e = err(&GOOD.replace("variance = 0.01", "variance = -1.0"));
    assert!(
        e.starts_with(
            "p.toml: line 11, column 1: pipeline 'kf': sensor /radar/speed: variance must be \
             positive"
        ),
        "{e}"
    );
    let e = err(&GOOD.replace("jerk_psd = 0.05", "jerk_psd = -0.05"));
    assert!(
        e.starts_with("p.toml: line 2, column 1: pipeline 'kf': motion.jerk_psd must be positive"),
        "{e}"
    );
    assert!(
        err(&GOOD.replace("jerk_psd = 0.05", "jerk_psd = 0.05, jerk_variance = 1.0"))
            .contains("exactly one")
    );
    assert!(
        err(&GOOD.replace("filter = \"kalman\"", "filter = \"magic\""))
            .contains("unknown kind `magic`")
    );
    assert!(err(&GOOD.replace("name = \"kf\"", "name = \"a/b\"")).contains("letters, digits"));
}

const FEDERATED: &str = r#"
[[pipeline]]
name = "fkf"
filter = "federated_kalman"
motion = { model = "singer", time_constant_s = 20.0, acceleration_std_mps2 = 0.3 }

[pipeline.federated]
feedback = "fusion_reset"
fusion_period_s = 1.0

[[pipeline.federated.band]]
below_kmh = 50.0
beta = { ins = 0.6, gnss = 0.3, radar = 0.1 }

[[pipeline.federated.band]]
beta = { ins = 0.4, gnss = 0.4, radar = 0.2 }

[[pipeline.sensor]]
topic = "/imu"
device = "ins"
fields = ["acceleration"]
variance = 0.001

[[pipeline.sensor]]
topic = "/gnss/fix"
device = "gnss"
variance = { chainage = "message", speed = 0.01 }

[[pipeline.sensor]]
topic = "/radar/speed"
device = "radar"
variance = "message"
"#;

#[test]
fn federated_bands_parse_into_the_device_order() {
    let c = Pipelines::parse(FEDERATED, Path::new("f.toml")).unwrap();
    let EstimatorSpec::FederatedKalman { federated } = &c.pipeline[0].estimator else {
        panic!("a federated Kalman pipeline");
    };
    let t = &federated.sharing;
    assert_eq!(t.at(10.0), &[0.6, 0.3, 0.1]);
    assert_eq!(t.at(100.0), &[0.4, 0.4, 0.2]);
    assert_eq!(c.pipeline[0].devices, vec!["ins", "gnss", "radar"]);
    let devices: Vec<_> = c.pipeline[0].sensors.iter().map(|s| s.device).collect();
    assert_eq!(devices, [0, 1, 2]);
}

#[test]
fn bad_federated_and_particle_configs_say_what_is_wrong() {
    let e = Pipelines::parse(
        &FEDERATED.replace("gnss = 0.3, radar = 0.1", "gnss = 0.3, radar = 0.2"),
        Path::new("f.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("pipeline 'fkf': federated.band below 50 km/h: β sums to 1.1, not 1"),
        "{e}"
    );
    let e = Pipelines::parse(
        &FEDERATED.replace("ins = 0.4, gnss", "odo = 0.4, gnss"),
        Path::new("f.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("β for 'odo', which is not a device"), "{e}");
    let e = Pipelines::parse(
        &FEDERATED.replace("federated_kalman", "federated_kalmann"),
        Path::new("f.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("line 4") && e.contains("unknown kind `federated_kalmann`"),
        "{e}"
    );
    let particle = GOOD.replace(
        "filter = \"kalman\"",
        "filter = \"particle\"\nparticle = { particles = 0 }",
    );
    assert!(err(&particle).contains("particle.particles must be at least 1"));
    assert!(err(&GOOD.replace("variance = 0.01", "variance = -0.01"))
        .contains("variance must be positive, not -0.01"));
    assert!(err(&GOOD.replace(
        "filter = \"kalman\"",
        "filter = \"kalman\"\nsmoother = true\noutput_rate_hz = 0.0"
    ))
    .contains("output_rate_hz must be positive"));
    let e = err(&GOOD.replace(
        "filter = \"kalman\"",
        "filter = \"particle\"\nsmoother = true",
    ));
    assert!(
        e.contains("smoother = true needs filter = \"kalman\""),
        "{e}"
    );
    let e = err(&GOOD.replace("jerk_psd = 0.05", "acceleration_psd = 0.05"));
    assert!(e.contains("unknown field `acceleration_psd`"), "{e}");
    let e = Pipelines::parse(
        &FEDERATED.replace(
            "filter = \"federated_kalman\"",
            "filter = \"federated_kalman\"\ngate_lockout = 5",
        ),
        Path::new("f.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("gate_lockout is for kalman and particle pipelines"),
        "{e}"
    );
}

/// The GOOD configuration with more keys in the loop's sensor table and the radar's.
fn with(loop_extra: &str, radar_extra: &str) -> String {
    GOOD.replace(
        "variance = \"message\"\n",
        &format!("variance = \"message\"\n{loop_extra}\n"),
    )
    .replace(
        "gate_nis = 16.0\n",
        &format!("gate_nis = 16.0\n{radar_extra}\n"),
    )
}

#[test]
fn sensor_states_parse_count_and_refuse_bad_values() {
    let good = with(
        "chainage_bias = { std_m = 2.0, time_constant_s = 60.0 }",
        "scale_factor = { std = 0.01 }",
    );
    let c = Pipelines::parse(&good, Path::new("p.toml")).unwrap();
    assert_eq!(c.pipeline[0].dimension(), 5);
    let kinds: Vec<_> = c.pipeline[0]
        .sensor_states()
        .iter()
        .map(|(i, s)| (*i, s.kind()))
        .collect();
    assert_eq!(kinds, [(0, "chainage_bias"), (1, "scale_factor")]);
    assert!(err(&with(
        "chainage_bias = { std_m = -2.0, time_constant_s = 60.0 }",
        ""
    ))
    .contains("chainage_bias.std_m must be positive"));
    assert!(err(&with(
        "",
        "scale_factor = { std = 0.01, walk_per_s = -1.0 }"
    ))
    .contains("walk_per_s must be ≥ 0"));
    assert!(err(&with("adaptive_variance = { window = 1 }", ""))
        .contains("adaptive_variance.window = 1: at least 2 innovations"));
    assert!(Pipelines::parse(
        &with("adaptive_variance = { window = 10 }", ""),
        Path::new("p.toml")
    )
    .is_ok());
    assert!(err(&with(
        "",
        "fields = [\"speed\"]\nchainage_bias = { std_m = 2.0, time_constant_s = 60.0 }"
    ))
    .contains("chainage is not among its fields"));
}

#[test]
fn sensor_state_quantities_speed_windows_and_the_state_limit() {
    // A chainage scale for the loop; a speed window for a speed sensor only, on a model
    // with acceleration.
    let c = Pipelines::parse(
        &with(
            "scale_factor = { std = 1e-4, quantity = \"chainage\" }",
            "speed_window_s = 0.2",
        ),
        Path::new("p.toml"),
    )
    .unwrap();
    assert_eq!(
        c.pipeline[0].sensor_states()[0].1.quantity(),
        Quantity::Chainage
    );
    assert_eq!(c.pipeline[0].sensors[1].speed_window_s, Some(0.2));
    let e = err(&with(
        "scale_factor = { std = 1e-4, quantity = \"acceleration\" }",
        "",
    ));
    assert!(e.contains("must be speed or chainage"), "{e}");
    let e = err(&with("fields = [\"chainage\"]\nspeed_window_s = 0.2", ""));
    assert!(
        e.contains("speed_window_s, but speed is not among its fields"),
        "{e}"
    );
    let e = err(&with("", "speed_window_s = 0.2").replace(
        "model = \"constant_acceleration\", jerk_psd = 0.05",
        "model = \"constant_velocity\", acceleration_psd = 0.05",
    ));
    assert!(e.contains("needs the acceleration"), "{e}");
    let e = err(&with("", "speed_window_s = -0.2"));
    assert!(e.contains("speed_window_s must be positive"), "{e}");
    let e = err(&with(
        "",
        "fields = [\"speed\"]\nacceleration_bias = { std_mps2 = 0.01, time_constant_s = 60.0 }",
    ));
    assert!(e.contains("acceleration_bias, but no acceleration"), "{e}");
    // The loop's bias and scale, the radar's scale and five odometers' scales:
    // 3 + 2 + 1 + 5 = 11 states.
    let odometer = |n: u32| {
        format!(
            "\n[[pipeline.sensor]]\ntopic = \"/odometer/{n}\"\nvariance = 0.1\n\
             scale_factor = {{ std = 0.01 }}\n"
        )
    };
    let e = err(&format!(
        "{}{}{}{}{}{}",
        with(
            "chainage_bias = { std_m = 2.0, time_constant_s = 60.0 }\nscale_factor = { std = 1e-4, quantity = \"chainage\" }",
            "scale_factor = { std = 0.01 }",
        ),
        odometer(1),
        odometer(2),
        odometer(3),
        odometer(4),
        odometer(5)
    ));
    assert!(
        e.contains("3 motion states and 8 sensor states: at most 10"),
        "{e}"
    );
}

#[test]
fn a_sensor_binds_to_a_channel_whose_model_gives_its_fields_or_says_why_not() {
    use railfuse_catalog::messages::MessageKind;
    let input = Path::new("run.mcap");
    let c = Pipelines::parse(GOOD, Path::new("p.toml")).unwrap();
    let p = &c.pipeline[0];
    let b = p
        .bind(input, 1, MessageKind::RadarSpeed.schema_name())
        .unwrap();
    assert_eq!(b.fields, [(Quantity::Speed, VarianceValue::Fixed(0.01))]);
    let e = p
        .bind(input, 1, MessageKind::Event.schema_name())
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(
            "run.mcap: pipeline 'kf' reads channel /radar/speed (p.toml line 11), which has \
             schema"
        ),
        "{e}"
    );
    let with = |extra: &str| {
        let text = GOOD.replace("gate_nis = 16.0", &format!("gate_nis = 16.0\n{extra}"));
        let c = Pipelines::parse(&text, Path::new("p.toml")).unwrap();
        c.pipeline[0]
            .bind(input, 1, MessageKind::RadarSpeed.schema_name())
            .unwrap_err()
            .to_string()
    };
    assert!(with("fields = [\"chainage\"]").ends_with("gives speed but not chainage"));
    let e = with("chainage_bias = { std_m = 1.0, time_constant_s = 10.0 }");
    assert!(
        e.ends_with("has a chainage_bias state but gives no chainage to observe it"),
        "{e}"
    );
    let text = GOOD.replace("variance = 0.01", "variance = { chainage = 0.01 }");
    let c = Pipelines::parse(&text, Path::new("p.toml")).unwrap();
    let e = c.pipeline[0]
        .bind(input, 1, MessageKind::RadarSpeed.schema_name())
        .unwrap_err()
        .to_string();
    assert!(
        e.ends_with("the sensor's variance table has no entry for it"),
        "{e}"
    );
}

/// FEDERATED without its band tables, with `sharing` set to `name` (or unset).
fn federated_named(name: Option<&str>, devices: [&str; 3]) -> Result<Pipelines> {
    let start = FEDERATED.find("[[pipeline.federated.band]]").unwrap();
    let end = FEDERATED.find("[[pipeline.sensor]]").unwrap();
    let mut text = format!("{}{}", &FEDERATED[..start], &FEDERATED[end..]);
    if let Some(name) = name {
        text = text.replace(
            "fusion_period_s = 1.0",
            &format!("fusion_period_s = 1.0\nsharing = \"{name}\""),
        );
    }
    // Through numbered tokens, so that renaming one device cannot rename another.
    for (i, from) in ["ins", "gnss", "radar"].iter().enumerate() {
        text = text.replace(&format!("device = \"{from}\""), &format!("device = #{i}#"));
    }
    for (i, to) in devices.iter().enumerate() {
        text = text.replace(&format!("device = #{i}#"), &format!("device = \"{to}\""));
    }
    Pipelines::parse(&text, Path::new("f.toml"))
}

fn sharing(c: &Pipelines) -> &SharingTable {
    match &c.pipeline[0].estimator {
        EstimatorSpec::FederatedKalman { federated } => &federated.sharing,
        _ => panic!("a federated Kalman pipeline"),
    }
}

#[test]
fn a_named_sharing_table_fits_the_device_names_or_is_refused_naming_them() {
    // Source 001's table, β mapped to the pipeline's device order by name.
    let c = federated_named(Some("source_001"), ["radar", "ins", "gnss"]).unwrap();
    assert_eq!(sharing(&c).at(10.0), &[0.1, 0.6, 0.3]);
    assert_eq!(sharing(&c).at(100.0), &[0.2, 0.4, 0.4]);
    // No table named: equal shares, whatever the devices are called.
    let c = federated_named(None, ["ins", "gnss", "radar"]).unwrap();
    assert_eq!(sharing(&c).at(10.0), &[1.0 / 3.0; 3]);
    // A table for other devices is an error naming both sets, never a silent fallback.
    let e = federated_named(Some("source_001"), ["imu", "gnss", "radar"])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            "sharing = \"source_001\" is for the devices ins, gnss, radar, but this \
             pipeline's devices are imu, gnss, radar"
        ),
        "{e}"
    );
    let e = federated_named(Some("source_000"), ["ins", "gnss", "radar"])
        .unwrap_err()
        .to_string();
    assert!(e.contains("is for the devices loop, radar"), "{e}");
    // Both a name and bands: refused.
    let both = FEDERATED.replace(
        "fusion_period_s = 1.0",
        "fusion_period_s = 1.0\nsharing = \"even\"",
    );
    let e = Pipelines::parse(&both, Path::new("f.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("give one or the other"), "{e}");
}
