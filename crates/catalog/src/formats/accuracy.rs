//! A receiver's or a phone's accuracy in metres (a radius that holds the position with a
//! stated probability) as the east/north/up covariance a fix carries: GPX points whose `hdop`
//! is an accuracy, logger CSVs with `hAcc`/`vAcc` columns.

/// The covariance of a horizontal accuracy `radius_m` and a vertical one, each holding the
/// true position with probability `confidence` (0 < p < 1), or each one σ (per horizontal
/// axis, and of the height) where no confidence is stated.
///
/// A circular normal of σ per axis holds p within r = σ √(−2 ln(1 − p)); one axis holds p
/// within z σ, z the normal quantile of (1 + p) / 2. Without a vertical accuracy the height
/// is taken as twice as uncertain as each horizontal axis (as receivers' VDOP ≈ 2 HDOP).
pub fn covariance_enu(radius_m: f64, vertical_m: Option<f64>, confidence: Option<f64>) -> [f64; 9] {
    let (sigma, vertical_sigma) = match confidence {
        Some(p) => (
            radius_m / (-2.0 * (1.0 - p).ln()).sqrt(),
            vertical_m.map(|v| v / normal_quantile((1.0 + p) / 2.0)),
        ),
        None => (radius_m, vertical_m),
    };
    let vertical = vertical_sigma.unwrap_or(2.0 * sigma);
    let (h, v) = (sigma * sigma, vertical * vertical);
    [h, 0.0, 0.0, 0.0, h, 0.0, 0.0, 0.0, v]
}

/// The standard normal's quantile (Acklam's rational approximation, relative error < 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_one_sigma_accuracy_is_sigma_and_a_68_percent_radius_is_narrower() {
        let c = covariance_enu(3.0, None, None);
        assert!(
            (c[0] - 9.0).abs() < 1e-9 && (c[8] - 36.0).abs() < 1e-9,
            "{c:?}"
        );
        let c = covariance_enu(3.0, Some(2.0), Some(0.68));
        let sigma = 3.0 / (-2.0 * 0.32f64.ln()).sqrt();
        assert!((c[4] - sigma * sigma).abs() < 1e-12);
        assert!((normal_quantile(0.84) - 0.994_457_883).abs() < 1e-6);
    }
}
