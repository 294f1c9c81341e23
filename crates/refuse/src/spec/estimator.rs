//! A pipeline's estimator validated: the four along the track with their settings
//! (particle, federated: β tables by speed band), or a registered kind built from its table.

use crate::checks::{at_least_zero, positive};
use crate::config::{FederatedConfig, FilterKind, PipelineConfig};
use crate::error::Result;
use crate::filter::federated::FederatedSettings;
use crate::filter::sharing::{SharingTable, SpeedBand};
use crate::kinds::PipelineKind;

use super::{EstimatorSpec, DEFAULT_GATE_LOCKOUT};

/// The estimator: one along the track with its settings, or the registered kind `kind` built
/// from its table.
pub(super) fn estimator(
    c: &PipelineConfig,
    filter: Option<FilterKind>,
    kind: Option<&dyn PipelineKind>,
    devices: &[String],
) -> Result<EstimatorSpec, String> {
    let lockout = c.gate_lockout.unwrap_or(DEFAULT_GATE_LOCKOUT);
    let federated_filter = filter.is_some_and(FilterKind::is_federated);
    if c.gate_lockout.is_some() && federated_filter {
        return Err(
            "gate_lockout is for kalman and particle pipelines; a federated pipeline's \
                    devices have [federated] detector.gate_failures"
                .into(),
        );
    }
    if c.smoother && filter != Some(FilterKind::Kalman) {
        return Err(format!(
            "smoother = true needs filter = \"kalman\" (the RTS smoother is linear), not \"{}\"",
            c.filter.get_ref()
        ));
    }
    if c.particle.is_some() && !filter.is_some_and(FilterKind::is_particle) {
        return Err(format!(
            "a [particle] section, but filter = \"{}\"",
            c.filter.get_ref()
        ));
    }
    if c.federated.is_some() && !federated_filter {
        return Err(format!(
            "a [federated] section, but filter = \"{}\"",
            c.filter.get_ref()
        ));
    }
    let particle = || {
        let p = c.particle.unwrap_or_default();
        p.check().map(|()| p)
    };
    let federated = || federated(&c.federated.clone().unwrap_or_default(), devices);
    Ok(match (filter, kind) {
        (Some(FilterKind::Kalman), _) => EstimatorSpec::Kalman {
            gate_lockout: lockout,
            smoother: c.smoother,
        },
        (Some(FilterKind::Particle), _) => EstimatorSpec::Particle {
            particle: particle()?,
            gate_lockout: lockout,
        },
        (Some(FilterKind::FederatedKalman), _) => EstimatorSpec::FederatedKalman {
            federated: federated()?,
        },
        (Some(FilterKind::FederatedParticle), _) => EstimatorSpec::FederatedParticle {
            federated: federated()?,
            particle: particle()?,
        },
        (None, Some(kind)) => {
            let settings = c.sections.get(kind.section()).map(|t| t.get_ref().clone());
            EstimatorSpec::Messages(kind.spec(c, settings)?)
        }
        (None, None) => unreachable!("the filter was looked up in the registry"),
    })
}

fn federated(f: &FederatedConfig, devices: &[String]) -> Result<FederatedSettings, String> {
    let fusion_period_s = at_least_zero("federated.fusion_period_s", f.fusion_period_s)?;
    positive("federated.detector.timeout_s", f.detector.timeout_s)?;
    positive(
        "federated.detector.agreement_chi2",
        f.detector.agreement_chi2,
    )?;
    at_least_zero(
        "federated.detector.max_exclusion_s",
        f.detector.max_exclusion_s,
    )?;
    at_least_zero(
        "federated.detector.consistency_chi2",
        f.detector.consistency_chi2,
    )?;
    if devices.is_empty() {
        return Err("a federated filter needs at least one device besides the master".into());
    }
    Ok(FederatedSettings {
        feedback: f.feedback,
        fusion: f.fusion,
        fusion_period_ns: (fusion_period_s * 1e9).round() as u64,
        sharing: sharing_table(f, devices)?,
        redistribution: f.redistribution,
        detector: f.detector,
    })
}

/// β by speed band, in device order: the configured bands, or the named table (equal shares
/// when none is named).
fn sharing_table(f: &FederatedConfig, devices: &[String]) -> Result<SharingTable, String> {
    let bands = f.band.as_slice();
    if bands.is_empty() {
        let name = f.sharing.unwrap_or_default();
        return SharingTable::named(name, devices).map_err(|e| format!("federated.{e}"));
    }
    if let Some(name) = f.sharing {
        return Err(format!(
            "federated: sharing = \"{}\" and [[pipeline.federated.band]] tables: give one or \
             the other",
            name.key()
        ));
    }
    let mut out = Vec::new();
    let mut last_below = 0.0;
    for (i, b) in bands.iter().enumerate() {
        let label = match b.below_kmh {
            Some(v) => format!("federated.band below {v} km/h"),
            None => "the last federated.band".to_owned(),
        };
        let below = match (b.below_kmh, i + 1 == bands.len()) {
            (Some(v), false) if v.is_finite() && v > last_below => v,
            (None, true) => f64::INFINITY,
            (Some(_), true) => {
                return Err(format!(
                    "{label}: the last band covers every higher speed, so it takes no below_kmh"
                ))
            }
            (None, false) => {
                return Err(format!(
                    "federated.band {}: only the last band may leave out below_kmh",
                    i + 1
                ))
            }
            (Some(v), false) => {
                return Err(format!(
                    "{label}: below_kmh must increase from band to band, not {v} after \
                     {last_below}"
                ))
            }
        };
        last_below = below;
        if let Some(name) = b.beta.keys().find(|n| !devices.contains(n)) {
            return Err(format!(
                "{label}: β for '{name}', which is not a device (devices: {})",
                devices.join(", ")
            ));
        }
        let mut beta = Vec::new();
        for d in devices {
            let v = *b
                .beta
                .get(d)
                .ok_or_else(|| format!("{label}: no β for device '{d}'"))?;
            beta.push(at_least_zero(&format!("{label}: β for '{d}'"), v)?);
        }
        let sum: f64 = beta.iter().sum();
        if (sum - 1.0).abs() > 1e-6 {
            return Err(format!(
                "{label}: β sums to {}, not 1 (information sharing needs Σβ = 1)",
                (sum * 1e6).round() / 1e6
            ));
        }
        out.push(SpeedBand {
            below_mps: below / 3.6,
            beta,
        });
    }
    Ok(SharingTable { bands: out })
}
