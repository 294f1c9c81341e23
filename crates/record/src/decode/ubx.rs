//! u-blox UBX frames: `b5 62`, class, id, little-endian u16 length, payload, Fletcher-8
//! checksum over class..payload. Decoded: NAV-PVT (position, velocity, time, fix type) and
//! NAV-COV (position covariance, NED).

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
    pub height_m: f64,
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

impl NavPvt {
    pub const CLASS_ID: (u8, u8) = (0x01, 0x07);

    pub fn decode(f: &Frame<'_>) -> Result<Self, UbxError> {
        let p = f.payload;
        if (f.class, f.id) != Self::CLASS_ID || p.len() != 92 {
            return Err(UbxError::BadPayload {
                class: f.class,
                id: f.id,
                len: p.len(),
            });
        }
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
            h_acc_m: u32le(p, 40) as f64 * 1e-3,
            v_acc_m: u32le(p, 44) as f64 * 1e-3,
            ground_speed_mps: i32le(p, 60) as f64 * 1e-3,
            heading_motion_rad: (i32le(p, 64) as f64 * 1e-5).to_radians(),
            speed_acc_mps: u32le(p, 68) as f64 * 1e-3,
        })
    }

    /// The fix type as railfuse names it: no position unless the receiver says the fix is
    /// good and it is a 2D/3D (or GNSS + DR) solution.
    pub fn railfuse_fix_type(&self) -> FixType {
        if !self.gnss_fix_ok || !matches!(self.fix_type, 2..=4) {
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
        let p = f.payload;
        if (f.class, f.id) != Self::CLASS_ID || p.len() != 64 {
            return Err(UbxError::BadPayload {
                class: f.class,
                id: f.id,
                len: p.len(),
            });
        }
        let c = |o| f32le(p, o) as f64;
        let (nn, ne, nd, ee, ed, dd) = (c(16), c(20), c(24), c(28), c(32), c(36));
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

/// Pairs each NAV-PVT with the NAV-COV of its epoch (the receiver sends it right after):
/// the solution is released with its covariance when that arrives, without it when the next
/// NAV-PVT comes first or the stream ends.
#[derive(Debug, Default, Clone)]
pub struct PvtCovPairing {
    pending: Option<NavPvt>,
}

impl PvtCovPairing {
    /// A NAV-PVT arrived: the one waiting before it, if any, is released without covariance.
    pub fn pvt(&mut self, pvt: NavPvt) -> Option<NavPvt> {
        self.pending.replace(pvt)
    }

    /// A NAV-COV arrived: the waiting NAV-PVT of its epoch with its covariance (when the
    /// receiver marks it valid), or `None` when no NAV-PVT of that epoch waits.
    pub fn cov(&mut self, cov: &NavCov) -> Option<(NavPvt, Option<[f64; 9]>)> {
        match self.pending.take() {
            Some(pvt) if pvt.itow_ms == cov.itow_ms => {
                Some((pvt, cov.pos_valid.then_some(cov.enu_m2)))
            }
            other => {
                self.pending = other;
                None
            }
        }
    }

    /// End of the stream: the solution still waiting, if any.
    pub fn finish(&mut self) -> Option<NavPvt> {
        self.pending.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
