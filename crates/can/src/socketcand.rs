//! The socketcand protocol (linux-can's CAN-over-TCP daemon, as python-can's `socketcand`
//! interface speaks it), in raw mode. The server greets with `< hi >`; the client sends
//! `< open can0 >` and `< rawmode >`, each answered `< ok >`; then every frame on the bus
//! arrives as an element:
//!
//! ```text
//! < frame 123 1700000000.123456 DEADBEEF >    11-bit id (3 digits), its time, its data
//! < frame 1ABCDEF0 1700000000.2 01 02 >       29-bit id (8 digits); data may be spaced
//! < error 20000004 1700000000.3 >             an error frame
//! ```
//!
//! The time is the server's (when its socket received the frame): the bus time.

use crate::frame::{Frame, ERROR_FLAG, MAX_CLASSIC_LEN};

/// The longest element: a frame of 8 bytes, spaced, with a long stamp. An element longer
/// than this is dropped (a broken or hostile server).
pub const MAX_ELEMENT: usize = 256;

/// What an element is.
#[derive(Debug, Clone, PartialEq)]
pub enum Element {
    Frame(Frame),
    /// `< hi >`, `< ok >`: the handshake.
    Hi,
    Ok,
    /// `< error … >` of a command (the server refused it), with its text.
    Refused(String),
    /// Anything else (statistics, echo of a mode): read past.
    Other(String),
}

/// The commands that open `bus` in raw mode, in order.
pub fn open_commands(bus: &str) -> [String; 2] {
    [format!("< open {bus} >"), "< rawmode >".to_owned()]
}

/// One element's text between `<` and `>`; the frame's `bus` is the caller's to set.
pub fn parse_element(text: &str) -> Result<Element, String> {
    let mut words = text.split_whitespace();
    let kind = words.next().unwrap_or("");
    match kind {
        "hi" => return Ok(Element::Hi),
        "ok" => return Ok(Element::Ok),
        "frame" | "error" => {}
        _ => return Ok(Element::Other(text.trim().to_owned())),
    }
    let id_text = words.next().ok_or("no id")?;
    let Some(stamp) = words.next() else {
        // `< error text >` without a frame's id and time: a refused command.
        return match kind {
            "error" => Ok(Element::Refused(id_text.to_owned())),
            _ => Err(format!("frame {id_text} has no time")),
        };
    };
    let raw = match u32::from_str_radix(id_text, 16) {
        Ok(raw) => raw,
        Err(_) if kind == "error" => return Ok(Element::Refused(text.trim().to_owned())),
        Err(_) => return Err(format!("id '{id_text}' is not hex")),
    };
    let stamp_ns = match crate::candump::parse_stamp(stamp) {
        Ok(t) => t,
        Err(_) if kind == "error" => return Ok(Element::Refused(text.trim().to_owned())),
        Err(e) => return Err(e),
    };
    let error = kind == "error" || (id_text.len() == 8 && raw & ERROR_FLAG != 0);
    let extended = !error && id_text.len() > 3;
    if extended && raw > 0x1FFF_FFFF || !extended && !error && raw > 0x7FF {
        return Err(format!("id '{id_text}' is beyond its bits"));
    }
    let data: String = words.collect();
    let data = crate::candump::parse_data(&data, MAX_CLASSIC_LEN)?;
    Ok(Element::Frame(Frame {
        stamp_ns,
        bus: String::new(),
        id: raw & 0x1FFF_FFFF,
        extended,
        rtr: false,
        error,
        fd: false,
        brs: false,
        esi: false,
        data,
    }))
}

/// The element of `frame` as socketcand sends it (for tests and simulated servers).
pub fn format_element(frame: &Frame) -> String {
    let id = match frame.extended {
        true => format!("{:08X}", frame.id),
        false => format!("{:03X}", frame.id),
    };
    let data: String = frame.data.iter().map(|b| format!("{b:02X}")).collect();
    format!(
        "< frame {id} {}.{:06} {data} >",
        frame.stamp_ns / 1_000_000_000,
        frame.stamp_ns % 1_000_000_000 / 1000
    )
}

/// Splits a server's byte stream into elements, bounded by [`MAX_ELEMENT`].
#[derive(Default)]
pub struct ElementSplitter {
    buf: Vec<u8>,
    inside: bool,
    overlong: bool,
}

/// One piece of a server's stream.
#[derive(Debug, PartialEq)]
pub enum Piece<'a> {
    Element(&'a str),
    /// Not text, or longer than [`MAX_ELEMENT`]: dropped.
    Unreadable,
}

impl ElementSplitter {
    /// Feeds `bytes`, calling `each` with every element completed.
    pub fn feed(&mut self, bytes: &[u8], mut each: impl FnMut(Piece<'_>)) {
        for &b in bytes {
            match (self.inside, b) {
                (false, b'<') => {
                    self.inside = true;
                    self.buf.clear();
                    self.overlong = false;
                }
                (false, _) => {}
                (true, b'>') => {
                    self.inside = false;
                    match (self.overlong, std::str::from_utf8(&self.buf)) {
                        (false, Ok(text)) => each(Piece::Element(text)),
                        _ => each(Piece::Unreadable),
                    }
                }
                (true, _) if self.buf.len() >= MAX_ELEMENT => self.overlong = true,
                (true, _) => self.buf.push(b),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_errors_and_the_handshake_read_and_a_frame_writes_back() {
        let Element::Frame(f) = parse_element(" frame 123 1700000000.123456 DEADBEEF ").unwrap()
        else {
            panic!()
        };
        assert_eq!(
            (f.id, f.extended, f.stamp_ns),
            (0x123, false, 1_700_000_000_123_456_000)
        );
        assert_eq!(f.data, [0xDE, 0xAD, 0xBE, 0xEF]);
        assert_eq!(
            format_element(&f),
            "< frame 123 1700000000.123456 DEADBEEF >"
        );
        let Element::Frame(f) = parse_element("frame 1ABCDEF0 1700000000.2 01 02").unwrap() else {
            panic!()
        };
        assert!(f.extended && f.id == 0x1ABC_DEF0 && f.data == [1, 2]);
        let Element::Frame(e) = parse_element("error 20000004 1700000000.3").unwrap() else {
            panic!()
        };
        assert!(e.error && e.id == 4);
        assert_eq!(parse_element(" hi ").unwrap(), Element::Hi);
        assert_eq!(parse_element("ok").unwrap(), Element::Ok);
        assert!(matches!(
            parse_element("error could not open").unwrap(),
            Element::Refused(_)
        ));
        assert!(parse_element("frame 800 1.0 00")
            .unwrap_err()
            .contains("beyond"));
        assert!(parse_element("frame 123 x 00")
            .unwrap_err()
            .contains("time stamp"));
        assert!(parse_element("frame 123 1.0 001122334455667788")
            .unwrap_err()
            .contains("more than 8"));
    }

    #[test]
    fn the_stream_splits_into_elements_and_an_overlong_one_is_dropped() {
        let mut s = ElementSplitter::default();
        let mut got = Vec::new();
        let stream = format!("< hi >< ok >\n< frame 1{} >< ok >", "0".repeat(300));
        for chunk in stream.as_bytes().chunks(7) {
            s.feed(chunk, |p| got.push(format!("{p:?}")));
        }
        assert_eq!(
            got,
            [
                "Element(\" hi \")",
                "Element(\" ok \")",
                "Unreadable",
                "Element(\" ok \")"
            ]
        );
    }
}
