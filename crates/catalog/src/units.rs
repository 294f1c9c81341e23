//! Units as loggers and DBCs write them, turned into the unit of a catalogue field: a CAN
//! signal's unit, a CSV column's stated unit. Each quantity's table lists the names it
//! accepts and each one's factor to the field's unit (degrees for `_deg` fields, SI
//! otherwise), so `km/h` into `speed_mps` is × 1/3.6 and `rad` into `latitude_deg` is × 180/π.

use std::f64::consts::PI;

/// A quantity's accepted unit names, each with its factor to the field's unit.
pub type Units = &'static [(&'static str, f64)];

pub const DEGREES: Units = &[
    ("deg", 1.0),
    ("°", 1.0),
    ("degree", 1.0),
    ("degrees", 1.0),
    ("rad", 180.0 / PI),
];
pub const RADIANS: Units = &[
    ("deg", PI / 180.0),
    ("°", PI / 180.0),
    ("degree", PI / 180.0),
    ("degrees", PI / 180.0),
    ("rad", 1.0),
    ("mrad", 0.001),
];
pub const METRES: Units = &[
    ("m", 1.0),
    ("km", 1000.0),
    ("ft", 0.3048),
    ("cm", 0.01),
    ("mm", 0.001),
];
pub const COUNT: Units = &[("", 1.0), ("-", 1.0)];
pub const SPEED: Units = &[
    ("m/s", 1.0),
    ("mps", 1.0),
    ("cm/s", 0.01),
    ("mm/s", 0.001),
    ("km/h", 1.0 / 3.6),
    ("kph", 1.0 / 3.6),
    ("kmh", 1.0 / 3.6),
    ("mph", 0.447_04),
    ("kn", 1852.0 / 3600.0),
    ("knots", 1852.0 / 3600.0),
];
pub const ACCELERATION: Units = &[
    ("m/s^2", 1.0),
    ("m/s²", 1.0),
    ("m/s2", 1.0),
    ("g", 9.806_65),
    ("mg", 0.009_806_65),
];
pub const RATE: Units = &[
    ("deg/s", PI / 180.0),
    ("°/s", PI / 180.0),
    ("dps", PI / 180.0),
    ("rad/s", 1.0),
    ("mrad/s", 0.001),
];

/// The factor of `unit` among `units` (names compared without case), or why not: "is in
/// 'furlong': a speed is in m/s, km/h, …".
pub fn factor(units: Units, unit: &str, what: &str) -> Result<f64, String> {
    let wanted = unit.trim().to_ascii_lowercase();
    units
        .iter()
        .find(|(u, _)| *u == wanted)
        .map(|(_, f)| *f)
        .ok_or_else(|| {
            let names: Vec<&str> = units
                .iter()
                .map(|(u, _)| *u)
                .filter(|u| !u.is_empty())
                .collect();
            format!("is in '{unit}': {what} is in {}", names.join(", "))
        })
}

/// The units a catalogue field is in, told by its name's suffix (`speed_mps`, `course_rad`,
/// `specific_force_mps2[0]`), with what the quantity is called; `None` for a field whose name
/// states no unit.
pub fn of_field(field: &str) -> Option<(Units, &'static str)> {
    let name = field.split('[').next().unwrap_or(field);
    let suffixes: [(&str, Units, &str); 6] = [
        ("_mps2", ACCELERATION, "an acceleration"),
        ("_radps", RATE, "an angular rate"),
        ("_mps", SPEED, "a speed"),
        ("_deg", DEGREES, "an angle in degrees"),
        ("_rad", RADIANS, "an angle"),
        ("_m", METRES, "a length"),
    ];
    suffixes
        .iter()
        .find(|(s, _, _)| name.ends_with(s))
        .map(|(_, u, what)| (*u, *what))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_field_s_suffix_says_its_units_and_a_unit_its_factor() {
        let (u, _) = of_field("speed_mps").unwrap();
        assert_eq!(factor(u, "mm/s", "a speed"), Ok(0.001));
        assert!((factor(u, "KM/H", "a speed").unwrap() - 1.0 / 3.6).abs() < 1e-15);
        let (u, _) = of_field("specific_force_mps2[2]").unwrap();
        assert_eq!(factor(u, "g", "x"), Ok(9.806_65));
        let (u, _) = of_field("course_rad").unwrap();
        assert!((factor(u, "deg", "x").unwrap() - PI / 180.0).abs() < 1e-15);
        assert_eq!(of_field("altitude_m").unwrap().0, METRES);
        assert!(of_field("satellites").is_none());
        let e = factor(SPEED, "furlong/fortnight", "a speed").unwrap_err();
        assert!(
            e.contains("'furlong/fortnight'") && e.contains("km/h"),
            "{e}"
        );
    }
}
