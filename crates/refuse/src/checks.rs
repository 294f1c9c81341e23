//! The checks a configuration's numbers go through, whichever table they sit in: one wording
//! for the pipeline table, its sensors and every pipeline kind's settings. Below the
//! configuration and every pipeline.

/// `v` if it is a positive number, else why not.
pub fn positive(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be positive, not {v}"))
    }
}

/// `v` if it is a number at least 0, else why not.
pub fn at_least_zero(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be ≥ 0, not {v}"))
    }
}

/// Every `(name, value)` of table `table` positive; the first that is not, named
/// `table.name`.
pub fn all_positive(table: &str, values: &[(&str, f64)]) -> Result<(), String> {
    for &(name, v) in values {
        positive(&format!("{table}.{name}"), v)?;
    }
    Ok(())
}

/// Every `(name, value)` of table `table` at least 0; the first that is not, named
/// `table.name`.
pub fn all_at_least_zero(table: &str, values: &[(&str, f64)]) -> Result<(), String> {
    for &(name, v) in values {
        at_least_zero(&format!("{table}.{name}"), v)?;
    }
    Ok(())
}
