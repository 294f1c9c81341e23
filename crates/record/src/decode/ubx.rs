//! u-blox UBX frames: `b5 62`, class, id, little-endian u16 length, payload, Fletcher-8
//! checksum over class..payload. Decoded: NAV-PVT (position, velocity, time, fix type),
//! NAV-COV (position covariance, NED) and NAV-HPPOSLLH (the position to 0.1 mm, which
//! replaces NAV-PVT's 1e-7° and 1 mm in the fix).
//!
//! What a receiver marks invalid is not used: a NAV-PVT without `validDate` and `validTime`
//! has no UTC (and a date off the calendar or `nano` outside ±1 s counts as none), one with
//! `gnssFixOK` 0 (the u-blox docs: "do not use"), `flags3.invalidLlh` or a latitude/longitude
//! off the globe has no position, a NAV-HPPOSLLH with `invalidLlh` is not applied, and a
//! NAV-COV with a non-finite value or a negative variance is refused.

use railfuse_catalog::messages::{FixType, GnssFix};

use super::time::unix_ns;

pub const SYNC: [u8; 2] = [0xb5, 0x62];
/// Largest payload accepted (the biggest messages u-blox receivers send are a few KiB).
pub const MAX_PAYLOAD: usize = 8192;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UbxError {
    #[error("no UBX sync bytes b5 62")]
    NoSync,
    #[error("UBX frame cut short")]
    Truncated,
    #[error("UBX payload of {0} bytes exceeds the {MAX_PAYLOAD}-byte limit")]
    TooLong(usize),
    #[error("UBX checksum {found:02x?} where the frame gives {expected:02x?}")]
    Checksum { expected: [u8; 2], found: [u8; 2] },
    #[error("UBX {class:02x}/{id:02x} with a {len}-byte payload of the wrong size")]
    BadPayload { class: u8, id: u8, len: usize },
    #[error("UBX NAV-COV with a covariance that is not finite or has a negative variance")]
    BadCovariance,
}

impl UbxError {
    /// The reason a frame is refused, as reports count it: one name per kind of problem.
    pub fn reason(&self) -> &'static str {
        match self {
            UbxError::NoSync => "no UBX sync bytes",
            UbxError::Truncated => "UBX frame cut short",
            UbxError::TooLong(_) => "UBX frame over the length limit",
            UbxError::Checksum { .. } => "UBX checksum failure",
            UbxError::BadPayload { .. } => "UBX payload of the wrong size",
            UbxError::BadCovariance => "UBX NAV-COV with an invalid covariance",
        }
    }
}

/// One checked frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame<'a> {
    pub class: u8,
    pub id: u8,
    pub payload: &'a [u8],
}

pub fn checksum(bytes: &[u8]) -> [u8; 2] {
    let (mut a, mut b) = (0u8, 0u8);
    for &x in bytes {
        a = a.wrapping_add(x);
        b = b.wrapping_add(a);
    }
    [a, b]
}

/// Parses the frame at the start of `bytes`; returns it and the bytes it used.
pub fn parse_frame(bytes: &[u8]) -> Result<(Frame<'_>, usize), UbxError> {
    if bytes.len() < 2 || bytes[..2] != SYNC {
        return Err(UbxError::NoSync);
    }
    if bytes.len() < 6 {
        return Err(UbxError::Truncated);
    }
    let len = u16::from_le_bytes([bytes[4], bytes[5]]) as usize;
    if len > MAX_PAYLOAD {
        return Err(UbxError::TooLong(len));
    }
    let end = 6 + len + 2;
    if bytes.len() < end {
        return Err(UbxError::Truncated);
    }
    let expected = [bytes[end - 2], bytes[end - 1]];
    let found = checksum(&bytes[2..end - 2]);
    if expected != found {
        return Err(UbxError::Checksum { expected, found });
    }
    Ok((
        Frame {
            class: bytes[2],
            id: bytes[3],
            payload: &bytes[6..6 + len],
        },
        end,
    ))
}

/// UBX-NAV-PVT (class 0x01, id 0x07, 92 bytes).
#[derive(Debug, Clone, PartialEq)]
pub struct NavPvt {
    pub itow_ms: u32,
    /// UTC of the solution, when the receiver says date and time are valid.
    pub utc_ns: Option<u64>,
    /// 0 no fix, 1 dead reckoning only, 2 2D, 3 3D, 4 GNSS + DR, 5 time only.
    pub fix_type: u8,
    pub gnss_fix_ok: bool,
    pub diff_soln: bool,
    /// 0 none, 1 RTK float, 2 RTK fixed.
    pub carr_soln: u8,
    pub num_sv: u8,
    pub lon_deg: f64,
    pub lat_deg: f64,
    /// Height above the ellipsoid.
    pub height_m: f64,
    /// Height above mean sea level.
    pub height_msl_m: f64,
    /// flags3.invalidLlh: the receiver says longitude, latitude and heights are not valid.
    pub invalid_llh: bool,
    pub h_acc_m: f64,
    pub v_acc_m: f64,
    pub ground_speed_mps: f64,
    pub heading_motion_rad: f64,
    pub speed_acc_mps: f64,
}

fn u16le(p: &[u8], o: usize) -> u16 {
    u16::from_le_bytes([p[o], p[o + 1]])
}
fn u32le(p: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]])
}
fn i32le(p: &[u8], o: usize) -> i32 {
    u32le(p, o) as i32
}
fn f32le(p: &[u8], o: usize) -> f32 {
    f32::from_bits(u32le(p, o))
}

/// The payload of `f` when it is message `class_id` of `len` bytes.
fn payload<'a>(f: &Frame<'a>, class_id: (u8, u8), len: usize) -> Result<&'a [u8], UbxError> {
    if (f.class, f.id) != class_id || f.payload.len() != len {
        return Err(UbxError::BadPayload {
            class: f.class,
            id: f.id,
            len: f.payload.len(),
        });
    }
    Ok(f.payload)
}

impl NavPvt {
    pub const CLASS_ID: (u8, u8) = (0x01, 0x07);

    pub fn decode(f: &Frame<'_>) -> Result<Self, UbxError> {
        let p = payload(f, Self::CLASS_ID, 92)?;
        let valid = p[11];
        let utc_ns = (valid & 0x03 == 0x03)
            .then(|| {
                unix_ns(
                    u16le(p, 4) as i64,
                    p[6] as u32,
                    p[7] as u32,
                    p[8] as u32,
                    p[9] as u32,
                    p[10] as u32,
                    i32le(p, 16) as i64,
                )
            })
            .flatten();
        let flags = p[21];
        Ok(NavPvt {
            itow_ms: u32le(p, 0),
            utc_ns,
            fix_type: p[20],
            gnss_fix_ok: flags & 0x01 != 0,
            diff_soln: flags & 0x02 != 0,
            carr_soln: flags >> 6,
            num_sv: p[23],
            lon_deg: i32le(p, 24) as f64 * 1e-7,
            lat_deg: i32le(p, 28) as f64 * 1e-7,
            height_m: i32le(p, 32) as f64 * 1e-3,
            height_msl_m: i32le(p, 36) as f64 * 1e-3,
            invalid_llh: p[78] & 0x01 != 0,
            h_acc_m: u32le(p, 40) as f64 * 1e-3,
            v_acc_m: u32le(p, 44) as f64 * 1e-3,
            ground_speed_mps: i32le(p, 60) as f64 * 1e-3,
            heading_motion_rad: (i32le(p, 64) as f64 * 1e-5).to_radians(),
            speed_acc_mps: u32le(p, 68) as f64 * 1e-3,
        })
    }

    /// The fix type as railfuse names it: no position unless the receiver says the fix is
    /// good, it is a 2D/3D (or GNSS + DR) solution, and its position is valid and on the globe.
    pub fn railfuse_fix_type(&self) -> FixType {
        let on_globe = self.lat_deg.abs() <= 90.0 && self.lon_deg.abs() <= 180.0;
        if !self.gnss_fix_ok || !matches!(self.fix_type, 2..=4) || self.invalid_llh || !on_globe {
            return FixType::None;
        }
        match (self.carr_soln, self.diff_soln) {
            (2, _) => FixType::RtkFixed,
            (1, _) => FixType::RtkFloat,
            (_, true) => FixType::Dgps,
            _ => FixType::Single,
        }
    }

    /// As a railfuse fix stamped `stamp_ns`; a fix without a position carries none.
    pub fn to_fix(&self, stamp_ns: u64, covariance_enu: Option<[f64; 9]>) -> GnssFix {
        let fix_type = self.railfuse_fix_type();
        let has = fix_type.has_position();
        let (h2, v2) = (self.h_acc_m.powi(2), self.v_acc_m.powi(2));
        GnssFix {
            stamp_ns,
            fix_type,
            satellites: self.num_sv,
            hdop: None,
            latitude_deg: has.then_some(self.lat_deg),
            longitude_deg: has.then_some(self.lon_deg),
            altitude_m: has.then_some(self.height_m),
            altitude_msl_m: has.then_some(self.height_msl_m),
            // hAcc is the receiver's horizontal 1σ estimate: split evenly over east and north.
            position_covariance_enu_m2: has.then(|| {
                covariance_enu.unwrap_or([h2 / 2.0, 0.0, 0.0, 0.0, h2 / 2.0, 0.0, 0.0, 0.0, v2])
            }),
            speed_mps: has.then_some(self.ground_speed_mps),
            course_rad: (has && self.ground_speed_mps > 0.5).then_some(self.heading_motion_rad),
        }
    }
}

/// UBX-NAV-COV (class 0x01, id 0x36, 64 bytes): position covariance in north/east/down.
#[derive(Debug, Clone, PartialEq)]
pub struct NavCov {
    pub itow_ms: u32,
    pub pos_valid: bool,
    /// Row-major ENU covariance (m²).
    pub enu_m2: [f64; 9],
}

impl NavCov {
    pub const CLASS_ID: (u8, u8) = (0x01, 0x36);

    pub fn decode(f: &Frame<'_>) -> Result<Self, UbxError> {
        let p = payload(f, Self::CLASS_ID, 64)?;
        let c = |o| f32le(p, o) as f64;
        let (nn, ne, nd, ee, ed, dd) = (c(16), c(20), c(24), c(28), c(32), c(36));
        let finite = [nn, ne, nd, ee, ed, dd].iter().all(|x| x.is_finite());
        if !finite || nn < 0.0 || ee < 0.0 || dd < 0.0 {
            return Err(UbxError::BadCovariance);
        }
        // NED → ENU: E = e, N = n, U = −d.
        let enu = [ee, ne, -ed, ne, nn, -nd, -ed, -nd, dd];
        Ok(NavCov {
            itow_ms: u32le(p, 0),
            pos_valid: p[5] != 0,
            enu_m2: enu,
        })
    }
}

/// Decodes a hex string (as the ETH logs write frames) into `out`; false if not hex.
pub fn hex_into(text: &str, out: &mut Vec<u8>) -> bool {
    out.clear();
    let b = text.as_bytes();
    if !b.len().is_multiple_of(2) {
        return false;
    }
    for pair in b.chunks_exact(2) {
        let nib = |c: u8| (c as char).to_digit(16);
        match (nib(pair[0]), nib(pair[1])) {
            (Some(h), Some(l)) => out.push((h * 16 + l) as u8),
            _ => return false,
        }
    }
    true
}

/// UBX-NAV-HPPOSLLH (class 0x01, id 0x14, 36 bytes): the position to 0.1 mm (F9 receivers).
#[derive(Debug, Clone, PartialEq)]
pub struct NavHpPosLlh {
    pub itow_ms: u32,
    /// flags.invalidLlh.
    pub invalid_llh: bool,
    pub lon_deg: f64,
    pub lat_deg: f64,
    pub height_m: f64,
    pub height_msl_m: f64,
    pub h_acc_m: f64,
    pub v_acc_m: f64,
}

impl NavHpPosLlh {
    pub const CLASS_ID: (u8, u8) = (0x01, 0x14);

    pub fn decode(f: &Frame<'_>) -> Result<Self, UbxError> {
        let p = payload(f, Self::CLASS_ID, 36)?;
        // The standard part (1e-7 °, mm) plus the high-precision part (1e-9 °, 0.1 mm).
        let hp = |o: usize| p[o] as i8 as f64;
        Ok(NavHpPosLlh {
            itow_ms: u32le(p, 4),
            invalid_llh: p[3] & 0x01 != 0,
            lon_deg: i32le(p, 8) as f64 * 1e-7 + hp(24) * 1e-9,
            lat_deg: i32le(p, 12) as f64 * 1e-7 + hp(25) * 1e-9,
            height_m: (i32le(p, 16) as f64 + hp(26) * 0.1) * 1e-3,
            height_msl_m: (i32le(p, 20) as f64 + hp(27) * 0.1) * 1e-3,
            h_acc_m: u32le(p, 28) as f64 * 1e-4,
            v_acc_m: u32le(p, 32) as f64 * 1e-4,
        })
    }
}

/// A solution ready: the NAV-PVT (with its epoch's NAV-HPPOSLLH precision applied) and its
/// epoch's NAV-COV covariance when the receiver sent one and marked it valid.
pub type Solution = (NavPvt, Option<[f64; 9]>);

/// A NAV-PVT waiting for the rest of its epoch.
#[derive(Debug, Clone)]
struct Epoch {
    pvt: NavPvt,
    /// Its NAV-COV arrived (`Some`), with the covariance when marked valid.
    cov: Option<Option<[f64; 9]>>,
    /// Its NAV-HPPOSLLH precision was applied.
    precise: bool,
}

/// Collects each NAV-PVT with the NAV-COV and NAV-HPPOSLLH of its epoch (same iTOW). A
/// solution is released when every message kind the stream has sent so far came for its
/// epoch, or, short of that, when the next NAV-PVT comes or the stream ends. NAV-COV follows
/// its NAV-PVT; NAV-HPPOSLLH may come on either side of it.
#[derive(Debug, Default, Clone)]
pub struct PvtCovPairing {
    pending: Option<Epoch>,
    /// A NAV-HPPOSLLH that came before its NAV-PVT.
    early_hp: Option<NavHpPosLlh>,
    cov_seen: bool,
    hp_seen: bool,
}

impl PvtCovPairing {
    /// A NAV-PVT arrived: the solution waiting before it, if any, is released as it is.
    pub fn pvt(&mut self, mut pvt: NavPvt) -> Option<Solution> {
        let before = self.release();
        let hp = self.early_hp.take().filter(|h| h.itow_ms == pvt.itow_ms);
        let precise = hp.is_some_and(|h| apply_hp(&mut pvt, &h));
        self.pending = Some(Epoch {
            pvt,
            cov: None,
            precise,
        });
        before
    }

    /// A NAV-COV arrived: the waiting NAV-PVT of its epoch takes it; released when complete.
    pub fn cov(&mut self, cov: &NavCov) -> Option<Solution> {
        self.cov_seen = true;
        match &mut self.pending {
            Some(e) if e.pvt.itow_ms == cov.itow_ms => {
                e.cov = Some(cov.pos_valid.then_some(cov.enu_m2))
            }
            _ => return None,
        }
        self.if_complete()
    }

    /// A NAV-HPPOSLLH arrived: the waiting NAV-PVT of its epoch takes its precision (or it
    /// waits for that NAV-PVT); released when complete.
    pub fn hp(&mut self, hp: NavHpPosLlh) -> Option<Solution> {
        self.hp_seen = true;
        match &mut self.pending {
            Some(e) if e.pvt.itow_ms == hp.itow_ms => {
                e.precise = apply_hp(&mut e.pvt, &hp) || e.precise
            }
            _ => {
                self.early_hp = Some(hp);
                return None;
            }
        }
        self.if_complete()
    }

    /// End of the stream: the solution still waiting, if any.
    pub fn finish(&mut self) -> Option<Solution> {
        self.release()
    }

    fn release(&mut self) -> Option<Solution> {
        self.pending.take().map(|e| (e.pvt, e.cov.flatten()))
    }

    fn if_complete(&mut self) -> Option<Solution> {
        let e = self.pending.as_ref()?;
        let complete = (e.cov.is_some() || !self.cov_seen) && (e.precise || !self.hp_seen);
        if complete {
            self.release()
        } else {
            None
        }
    }
}

/// The NAV-PVT's position to NAV-HPPOSLLH's precision; false (unchanged) where the receiver
/// marks the precise position invalid.
fn apply_hp(pvt: &mut NavPvt, hp: &NavHpPosLlh) -> bool {
    if hp.invalid_llh {
        return false;
    }
    pvt.lat_deg = hp.lat_deg;
    pvt.lon_deg = hp.lon_deg;
    pvt.height_m = hp.height_m;
    pvt.height_msl_m = hp.height_msl_m;
    pvt.h_acc_m = hp.h_acc_m;
    pvt.v_acc_m = hp.v_acc_m;
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of `class`/`id` around `payload`, with its checksum.
    fn frame(class: u8, id: u8, payload: &[u8]) -> Vec<u8> {
        let mut f = vec![0xb5, 0x62, class, id];
        f.extend_from_slice(&(payload.len() as u16).to_le_bytes());
        f.extend_from_slice(payload);
        let c = checksum(&f[2..]);
        f.extend_from_slice(&c);
        f
    }

    #[test]
    fn what_the_receiver_marks_invalid_or_off_the_calendar_is_not_used() {
        let mut p = vec![0u8; 92];
        p[4..6].copy_from_slice(&2024u16.to_le_bytes());
        (p[6], p[7], p[8], p[9], p[10], p[11]) = (12, 31, 23, 59, 59, 0x07);
        (p[20], p[21]) = (3, 0x01); // 3D, gnssFixOK
        p[28..32].copy_from_slice(&480_000_000i32.to_le_bytes());
        let decode = |p: &[u8]| {
            let f = frame(0x01, 0x07, p);
            NavPvt::decode(&parse_frame(&f).unwrap().0).unwrap()
        };
        let good = decode(&p);
        assert!(good.utc_ns.is_some() && good.railfuse_fix_type() == FixType::Single);
        let mut invalid_llh = p.clone();
        invalid_llh[78] = 0x01;
        assert_eq!(decode(&invalid_llh).railfuse_fix_type(), FixType::None);
        assert_eq!(decode(&invalid_llh).to_fix(1, None).latitude_deg, None);
        // 31 December, month 13, and second 60 at 23:58 (not a leap second).
        for (at, value) in [(7, 32u8), (6, 13), (10, 60)] {
            let mut bad = p.clone();
            (bad[9], bad[at]) = (58, value);
            assert_eq!(decode(&bad).utc_ns, None, "byte {at} = {value}");
        }
        let mut nano = p.clone();
        nano[16..20].copy_from_slice(&2_000_000_000i32.to_le_bytes());
        assert_eq!(decode(&nano).utc_ns, None);
        // NAV-COV: a NaN or a negative variance is refused.
        for (at, value) in [(16, f32::NAN), (28, -1.0f32), (36, f32::INFINITY)] {
            let mut c = vec![0u8; 64];
            c[5] = 1;
            c[at..at + 4].copy_from_slice(&value.to_le_bytes());
            let f = frame(0x01, 0x36, &c);
            let got = NavCov::decode(&parse_frame(&f).unwrap().0);
            assert_eq!(got, Err(UbxError::BadCovariance), "offset {at}: {value}");
        }
    }

    /// A NAV-PVT payload of a valid 3D fix at `itow_ms`.
    fn pvt_payload(itow_ms: u32) -> Vec<u8> {
        let mut p = vec![0u8; 92];
        p[0..4].copy_from_slice(&itow_ms.to_le_bytes());
        p[4..6].copy_from_slice(&2025u16.to_le_bytes());
        (p[6], p[7], p[8], p[9], p[10], p[11]) = (3, 21, 13, 58, 6, 0x07);
        (p[20], p[21], p[23]) = (3, 0x01 | 0x02 | (2 << 6), 21); // 3D, gnssFixOK, RTK fixed
        p[24..28].copy_from_slice(&7_647_025i32.to_le_bytes());
        p[28..32].copy_from_slice(&473_834_140i32.to_le_bytes());
        p[32..36].copy_from_slice(&111_936i32.to_le_bytes());
        p[36..40].copy_from_slice(&63_640i32.to_le_bytes());
        p
    }

    fn pvt(p: &[u8]) -> NavPvt {
        let f = frame(0x01, 0x07, p);
        NavPvt::decode(&parse_frame(&f).unwrap().0).unwrap()
    }

    #[test]
    fn gnss_fix_ok_0_is_no_position_whatever_the_fix_type() {
        let mut p = pvt_payload(1000);
        assert_eq!(pvt(&p).railfuse_fix_type(), FixType::RtkFixed);
        p[21] &= !0x01;
        let f = pvt(&p).to_fix(1, None);
        assert_eq!(
            (f.fix_type, f.latitude_deg, f.satellites),
            (FixType::None, None, 21)
        );
    }

    #[test]
    fn hpposllh_gives_the_position_to_a_tenth_of_a_millimetre_in_either_order() {
        let hp = |itow: u32, invalid: bool| {
            let mut h = vec![0u8; 36];
            h[3] = u8::from(invalid);
            h[4..8].copy_from_slice(&itow.to_le_bytes());
            h[8..12].copy_from_slice(&7_647_025i32.to_le_bytes());
            h[12..16].copy_from_slice(&473_834_140i32.to_le_bytes());
            h[16..20].copy_from_slice(&111_936i32.to_le_bytes());
            h[20..24].copy_from_slice(&63_640i32.to_le_bytes());
            (h[24], h[25], h[26], h[27]) = (37, (-42i8) as u8, 7, (-3i8) as u8);
            h[28..32].copy_from_slice(&141u32.to_le_bytes()); // 14.1 mm
            h[32..36].copy_from_slice(&235u32.to_le_bytes());
            let f = frame(0x01, 0x14, &h);
            NavHpPosLlh::decode(&parse_frame(&f).unwrap().0).unwrap()
        };
        let want_lat = 47.383_414 - 42e-9;
        let check = |(p, _): Solution| {
            assert!((p.lat_deg - want_lat).abs() < 1e-12, "{}", p.lat_deg);
            assert!((p.lon_deg - (0.764_702_5 + 37e-9)).abs() < 1e-12);
            assert!(
                (p.height_m - 111.9367).abs() < 1e-9 && (p.height_msl_m - 63.6397).abs() < 1e-9
            );
            assert!((p.h_acc_m - 0.0141).abs() < 1e-12);
        };
        // PVT, then HPPOSLLH: a stream without NAV-COV releases it at once.
        let mut pairing = PvtCovPairing::default();
        assert!(pairing.pvt(pvt(&pvt_payload(1000))).is_none());
        check(pairing.hp(hp(1000, false)).unwrap());
        // HPPOSLLH first (another message order), and NAV-COV in the stream: the solution
        // waits for both.
        let mut pairing = PvtCovPairing::default();
        assert!(pairing.hp(hp(2000, false)).is_none());
        assert!(pairing.pvt(pvt(&pvt_payload(2000))).is_none());
        let mut c = vec![0u8; 64];
        c[0..4].copy_from_slice(&2000u32.to_le_bytes());
        c[5] = 1;
        let f = frame(0x01, 0x36, &c);
        let cov = NavCov::decode(&parse_frame(&f).unwrap().0).unwrap();
        let solution = pairing.cov(&cov).unwrap();
        assert!(solution.1.is_some());
        check(solution);
        // Marked invalid: NAV-PVT's own position stands; another epoch's is not applied.
        let mut pairing = PvtCovPairing::default();
        pairing.pvt(pvt(&pvt_payload(3000)));
        assert!(
            pairing.hp(hp(3000, true)).is_none(),
            "waits: no precise position came"
        );
        let (p, _) = pairing.finish().unwrap();
        assert!((p.lat_deg - 47.383_414).abs() < 1e-12);
        let mut pairing = PvtCovPairing::default();
        assert!(pairing.hp(hp(999, false)).is_none());
        pairing.pvt(pvt(&pvt_payload(4000)));
        assert!((pairing.finish().unwrap().0.lat_deg - 47.383_414).abs() < 1e-12);
    }

    #[test]
    fn ack_frames_check_and_a_flipped_byte_fails_the_checksum() {
        let mut b = Vec::new();
        assert!(hex_into("b56205010200068a98c1", &mut b));
        let (f, used) = parse_frame(&b).unwrap();
        assert_eq!(
            (f.class, f.id, f.payload, used),
            (0x05, 0x01, &[0x06, 0x8a][..], 10)
        );
        b[6] ^= 1;
        assert!(matches!(parse_frame(&b), Err(UbxError::Checksum { .. })));
        assert_eq!(parse_frame(&b[..7]), Err(UbxError::Truncated));
        let mut long = b.clone();
        long[4] = 0xff;
        long[5] = 0xff;
        assert_eq!(parse_frame(&long), Err(UbxError::TooLong(0xffff)));
    }
}
