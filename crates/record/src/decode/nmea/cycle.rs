//! One reporting cycle: what the sentences of one epoch said, and the one fix they make
//! (the combination rules are the module doc's, "One cycle, one fix").

use std::collections::BTreeSet;

use railfuse_catalog::messages::{FixType, GnssFix};

use super::fields::rank;
use super::sentences::{Kind, Part, Position, Talker, COMBINED};
use crate::decode::time::Date;

/// Position reports kept per cycle (one per talker and type; a receiver sends a handful).
const MAX_POSITIONS: usize = 16;
/// Satellites listed per cycle (every constellation's GSAs together).
const MAX_SATELLITES: usize = 256;
/// Once-per-epoch sentences remembered per cycle.
const MAX_SEEN: usize = 64;

/// One reporting cycle.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Cycle {
    /// Its time of day (ns since midnight); `None` while only untimed sentences came.
    pub tod_ns: Option<u64>,
    /// A sentence that carries the epoch's time came without one before the cycle had a
    /// time: an epoch the receiver could not time (rule 3).
    pub untimed_epoch: bool,
    pub date: Option<Date>,
    positions: Vec<Position>,
    speed_mps: Option<f64>,
    course_rad: Option<f64>,
    /// GSAs that gave a fix mode, and how many of them said "no fix".
    gsa_modes: u32,
    gsa_no_fix: u32,
    /// Satellites used, listed by the GSAs that said there is a fix.
    gsa_satellites: BTreeSet<(u8, u32)>,
    gsa_hdop: Option<f64>,
    /// (σ lat, σ lon, σ alt) in metres from this cycle's GST.
    sigmas: Option<(f64, f64, f64)>,
    /// The once-per-epoch sentences (talker, type) this cycle holds (rule 2).
    seen: Vec<(Talker, Kind)>,
}

impl Cycle {
    pub fn at(tod_ns: Option<u64>) -> Self {
        Cycle {
            tod_ns,
            ..Cycle::default()
        }
    }

    /// True when this cycle already holds `kind` from `talker` and so cannot take another.
    pub fn holds(&self, talker: Talker, kind: Kind) -> bool {
        kind.once_per_epoch() && self.seen.contains(&(talker, kind))
    }

    /// A sentence's part added to the reporting cycle.
    pub fn add(&mut self, talker: Talker, kind: Kind, part: Part) {
        if kind.once_per_epoch()
            && !self.seen.contains(&(talker, kind))
            && self.seen.len() < MAX_SEEN
        {
            self.seen.push((talker, kind));
        }
        match part {
            Part::Position(p) => self.position(p),
            Part::Rmc(p, date, motion) => {
                self.position(p);
                self.date = date.or(self.date);
                if let Some(m) = motion {
                    (self.speed_mps, self.course_rad) = (m.speed_mps, m.course_rad);
                }
            }
            Part::Zda(date) => self.date = Some(date),
            Part::Vtg(motion) => {
                if let Some(m) = motion {
                    self.speed_mps = m.speed_mps.or(self.speed_mps);
                    self.course_rad = m.course_rad.or(self.course_rad);
                }
            }
            Part::Gsa(g) => {
                if let Some(no_fix) = g.no_fix {
                    self.gsa_modes += 1;
                    self.gsa_no_fix += u32::from(no_fix);
                    if !no_fix {
                        for s in g.satellites {
                            if self.gsa_satellites.len() < MAX_SATELLITES {
                                self.gsa_satellites.insert(s);
                            }
                        }
                    }
                }
                self.gsa_hdop = self.gsa_hdop.or(g.hdop);
            }
            Part::Gst(sigmas) => self.sigmas = sigmas,
        }
    }

    /// A position report: one per talker and type (a repeat replaces it).
    fn position(&mut self, p: Position) {
        let same = |q: &Position| (q.talker, q.kind) == (p.talker, p.kind);
        if let Some(i) = self.positions.iter().position(same) {
            self.positions[i] = p;
        } else if self.positions.len() < MAX_POSITIONS {
            self.positions.push(p);
        }
    }

    /// True when the cycle reported a position sentence (it makes a fix when it ends).
    pub fn has_position_report(&self) -> bool {
        !self.positions.is_empty()
    }

    /// The position report the fix is made of: the best by the module's order, the first
    /// received among equals.
    fn chosen(&self) -> Option<&Position> {
        let key = |p: &Position| {
            (
                p.kind.is_fix_sentence(),
                p.talker == COMBINED,
                rank(p.fix_type),
                p.kind == Kind::Gga,
            )
        };
        let mut best: Option<&Position> = None;
        for p in &self.positions {
            if best.is_none_or(|b| key(p) > key(b)) {
                best = Some(p);
            }
        }
        best
    }

    /// Satellites used, over every constellation of the cycle.
    fn satellites(&self, chosen: &Position) -> u32 {
        let fix_sentences = || self.positions.iter().filter(|p| p.kind.is_fix_sentence());
        let mut talkers: Vec<Talker> = fix_sentences().map(|p| p.talker).collect();
        talkers.sort_unstable();
        talkers.dedup();
        let gsa = (!self.gsa_satellites.is_empty()).then_some(self.gsa_satellites.len() as u32);
        if (chosen.talker == COMBINED && chosen.satellites.is_some()) || talkers.len() <= 1 {
            return chosen.satellites.or(gsa).unwrap_or(0);
        }
        gsa.unwrap_or_else(|| {
            // Each talker's count once (its largest, should it send GGA and GNS).
            talkers
                .iter()
                .map(|t| {
                    fix_sentences()
                        .filter(|p| p.talker == *t)
                        .filter_map(|p| p.satellites)
                        .max()
                        .unwrap_or(0)
                })
                .sum()
        })
    }

    /// The cycle's fix, stamped `stamp_ns`; `None` without a position report.
    pub fn fix(&self, stamp_ns: u64) -> Option<GnssFix> {
        let g = self.chosen()?;
        let gsa_says_no_fix = self.gsa_modes > 0 && self.gsa_no_fix == self.gsa_modes;
        let unsafe_status = self.positions.iter().any(|p| p.unsafe_status);
        let fix_type = match gsa_says_no_fix || unsafe_status {
            true => FixType::None,
            false => g.fix_type,
        };
        let has = fix_type.has_position() && g.latitude_deg.is_some() && g.longitude_deg.is_some();
        let with = |x: Option<f64>| x.filter(|_| has);
        Some(GnssFix {
            stamp_ns,
            fix_type: if has { fix_type } else { FixType::None },
            satellites: self.satellites(g).min(255) as u8,
            hdop: g.hdop.or(self.gsa_hdop),
            latitude_deg: with(g.latitude_deg),
            longitude_deg: with(g.longitude_deg),
            altitude_m: with(g.msl_m.zip(g.separation_m).map(|(h, n)| h + n)),
            altitude_msl_m: with(g.msl_m),
            position_covariance_enu_m2: self
                .sigmas
                .filter(|_| has)
                .map(|(sn, se, su)| [se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, su * su]),
            speed_mps: with(self.speed_mps),
            course_rad: with(self.course_rad),
        })
    }
}
