//! Source 004's two-stage Butterworth filtering (§3.1): a fixed low-pass that removes the
//! interference above the signal (1000 Hz), then a band-pass that follows the speed around the
//! sleeper (clamp) frequency `v / spacing` (20 m/s over 0.6 m sleepers: about 33 Hz, band
//! 20–40 Hz). Both of order 4 as scipy counts it (`butter(4, …)`: the band-pass has eight
//! poles), designed by `sci-rs` (a translation of scipy's `butter`, second-order sections) and
//! run section by section (scipy's `sosfilt`) with their state kept from block to block.
//!
//! Which stage feeds what (the source leaves it open): the band-passed signal is nearly a
//! sine at the sleeper frequency, good for counting sleepers and useless for the speed
//! correlation, whose peak would repeat every sleeper; the correlator takes the low-passed
//! signal, where switches, cables, defects and sleeper-to-sleeper differences make the peak
//! unique.

use sci_rs::signal::filter::design::{
    butter_dyn, DigitalFilter, FilterBandType, FilterOutputType, Sos,
};
use sci_rs::signal::filter::sosfilt_item;

/// Order of both stages (scipy's `N`).
pub const ORDER: usize = 4;

/// A Butterworth filter as second-order sections, with its state.
#[derive(Debug, Clone)]
pub struct Butterworth {
    sections: Vec<Sos<f64>>,
}

impl Butterworth {
    /// Low-pass at `cutoff_hz` for samples at `fs_hz`.
    pub fn lowpass(cutoff_hz: f64, fs_hz: f64) -> Result<Self, String> {
        Self::design(vec![cutoff_hz], FilterBandType::Lowpass, fs_hz)
    }

    /// Band-pass from `low_hz` to `high_hz`.
    pub fn bandpass(low_hz: f64, high_hz: f64, fs_hz: f64) -> Result<Self, String> {
        if low_hz >= high_hz {
            return Err(format!(
                "a band-pass needs its low edge ({low_hz} Hz) below its high edge ({high_hz} Hz)"
            ));
        }
        Self::design(vec![low_hz, high_hz], FilterBandType::Bandpass, fs_hz)
    }

    fn design(edges: Vec<f64>, band: FilterBandType, fs_hz: f64) -> Result<Self, String> {
        let nyquist = fs_hz / 2.0;
        if let Some(e) = edges
            .iter()
            .find(|&&e| !(e.is_finite() && e > 0.0 && e < nyquist))
        {
            return Err(format!(
                "a filter edge of {e} Hz is outside (0, {nyquist}) Hz, half the sample rate"
            ));
        }
        match butter_dyn(
            ORDER,
            edges,
            Some(band),
            Some(false),
            Some(FilterOutputType::Sos),
            Some(fs_hz),
        ) {
            DigitalFilter::Sos(s) => Ok(Butterworth { sections: s.sos }),
            _ => Err("the Butterworth design gave no second-order sections".into()),
        }
    }

    /// One sample through the filter.
    #[inline]
    pub fn step(&mut self, x: f64) -> f64 {
        sosfilt_item(x, &mut self.sections)
    }

    /// New coefficients, the state kept: the band-pass follows the speed without starting
    /// over (a transient in proportion to the change, small for the few-percent steps it is
    /// retuned in).
    pub fn retune(&mut self, other: &Butterworth) {
        for (s, o) in self.sections.iter_mut().zip(&other.sections) {
            s.b = o.b;
            s.a = o.a;
        }
    }

    /// Back to rest (after a gap in the signal).
    pub fn reset(&mut self) {
        for s in &mut self.sections {
            s.zi0 = 0.0;
            s.zi1 = 0.0;
        }
    }

    /// The sections as scipy writes them: `[b0, b1, b2, a0, a1, a2]` each.
    pub fn sos(&self) -> Vec<[f64; 6]> {
        self.sections
            .iter()
            .map(|s| [s.b[0], s.b[1], s.b[2], s.a[0], s.a[1], s.a[2]])
            .collect()
    }
}

/// The speed-following band: `[0.6, 1.2]` × the sleeper frequency `v / spacing` (the
/// source's 20–40 Hz around 33 Hz), kept between `floor_hz` and below Nyquist.
pub fn sleeper_band(speed_mps: f64, spacing_m: f64, floor_hz: f64, fs_hz: f64) -> (f64, f64) {
    let f = (speed_mps.abs() / spacing_m).max(floor_hz / 0.6);
    let high = (1.2 * f).min(0.45 * fs_hz);
    ((0.6 * f).min(high * 0.5), high)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The gain at `f_hz` of a filter, measured on a long sine after its transient (RMS
    /// out over RMS in).
    fn gain(mut f: Butterworth, f_hz: f64, fs: f64) -> f64 {
        let n = (fs * 4.0) as usize;
        let mut power = 0.0;
        for k in 0..n {
            let y = f.step((std::f64::consts::TAU * f_hz * k as f64 / fs).sin());
            if k >= n / 2 {
                power += y * y;
            }
        }
        (2.0 * power / (n - n / 2) as f64).sqrt()
    }

    #[test]
    fn the_stages_pass_their_band_and_stop_the_rest() {
        let fs = 10_000.0;
        let lp = Butterworth::lowpass(1000.0, fs).unwrap();
        assert!((gain(lp.clone(), 100.0, fs) - 1.0).abs() < 1e-3);
        // −3 dB at the cutoff, −24 dB an octave above (order 4).
        assert!((gain(lp.clone(), 1000.0, fs) - 0.5f64.sqrt()).abs() < 1e-2);
        assert!(gain(lp, 2000.0, fs) < 0.07);
        let (lo, hi) = sleeper_band(20.0, 0.6, 0.5, fs);
        assert!((lo - 20.0).abs() < 1e-9 && (hi - 40.0).abs() < 1e-9);
        let bp = Butterworth::bandpass(lo, hi, fs).unwrap();
        assert!((gain(bp.clone(), 28.3, fs) - 1.0).abs() < 0.02);
        assert!(gain(bp.clone(), 5.0, fs) < 0.01);
        assert!(gain(bp, 200.0, fs) < 0.01);
    }

    #[test]
    fn an_edge_at_or_above_nyquist_is_refused_with_the_reason() {
        let e = Butterworth::lowpass(6000.0, 10_000.0).unwrap_err();
        assert!(e.contains("outside (0, 5000) Hz"), "{e}");
        assert!(Butterworth::bandpass(40.0, 20.0, 10_000.0).is_err());
    }
}
